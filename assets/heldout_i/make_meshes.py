"""Writes held-out set I's mesh bodies (run once; the STL files are committed).

    .venv/bin/python assets/heldout_i/make_meshes.py

Written before any episode on them and before the change to the
tight-fit tasks' contact generation was committed: its clean check. Bodies and entries a
machined part has that no earlier set has: a hexagonal prism and a round disc with the hole
off-centre near their edge, a cross-shaped body whose re-entrant corners are 1 cm from the
opening, a notch through the body 8 mm from the opening, a shallow counterbore. Metres,
bottom at z = 0; every hole at x = y = 0 (the hole itself is cut by the hole library from the
.yaml)."""

from pathlib import Path

from trimesh.creation import box, cylinder
from trimesh.transformations import translation_matrix as at

from cfvs_maniskill.objects.meshes import solid, write_bodies

HERE = Path(__file__).parent


meshes = {
    # A hexagonal prism 18 cm across its corners, 5.5 cm tall; the hole 4 cm off its centre,
    # so the opening's side is 1.3 cm from a face of the prism.
    "hex_prism": solid(
        [cylinder(radius=0.09, height=0.055, sections=6, transform=at([-0.04, 0, 0.0275]))]
    ),
    # A round disc 14 cm across, 5 cm tall; the hole 2.5 cm off its centre: the opening's
    # far corners are 1.4 cm from the rim.
    "round_disc": solid([cylinder(radius=0.07, height=0.05, transform=at([-0.025, 0, 0.025]))]),
    # A cross 22 cm across with arms 7 cm wide: the re-entrant corners 1 cm from the opening.
    "cross_block": solid(
        [
            box([0.22, 0.07, 0.05], transform=at([0, 0, 0.025])),
            box([0.07, 0.22, 0.05], transform=at([0, 0, 0.025])),
        ]
    ),
    # A notch 1.5 cm wide cut through the body's full height from one edge, its end 8 mm
    # from the opening's side.
    "notched_block": solid(
        [box([0.20, 0.20, 0.05], transform=at([0, 0, 0.025]))],
        [box([0.08, 0.015, 0.06], transform=at([0.073, 0, 0.025]))],
    ),
    # A counterbore 6.2 cm square and 1.5 mm deep round the opening: the hole opens on
    # its floor (the .yaml's origin).
    "counterbored": solid(
        [box([0.20, 0.20, 0.05], transform=at([0, 0, 0.025]))],
        [box([0.062, 0.062, 0.0115], transform=at([0, 0, 0.0485 + 0.00575]))],
    ),
}
write_bodies(meshes, HERE)
