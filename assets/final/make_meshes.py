"""Writes the frozen final set's mesh bodies (run once; the STL files are committed).

    .venv/bin/python assets/final/make_meshes.py

Written once, before any episode on them, and never to be traced or used to choose
anything: the set for the README's generalisation claim (docs/evaluation.md). Families
no earlier set has: a gusset beside the opening, a frustum whose flat top barely holds it,
a rim of teeth, a V-groove across the body, a wedge with the hole on its sloped face.
Metres, bottom at z = 0, the opening at x = y = 0; the hole itself is cut by the hole
library from the .yaml."""

from pathlib import Path

import numpy as np
from trimesh.convex import convex_hull
from trimesh.creation import box, cylinder, revolve
from trimesh.transformations import rotation_matrix
from trimesh.transformations import translation_matrix as at

from cfvs_maniskill.objects.meshes import solid, write_bodies

HERE = Path(__file__).parent


def prism_xz(points: list[tuple[float, float]], width: float):
    """A convex prism whose cross-section is `points` in the x-z plane, `width` along y,
    centred on y = 0."""
    return convex_hull([(x, y, z) for x, z in points for y in (-width / 2, width / 2)])


def gear(teeth: int, r_root: float, depth: float, height: float):
    """A disc of radius `r_root` with `teeth` teeth `depth` deep round its rim."""
    width = 2 * np.pi * r_root / teeth * 0.4
    parts = [cylinder(radius=r_root, height=height, sections=96, transform=at([0, 0, height / 2]))]
    for k in range(teeth):
        tooth = box([2 * depth, width, height], transform=at([r_root, 0, height / 2]))
        parts.append(tooth.apply_transform(rotation_matrix(2 * np.pi * k / teeth, [0, 0, 1])))
    return solid(parts)


meshes = {
    # A plate 20 x 16 cm, 5 cm thick; a wall 6 cm taller along one end and a gusset 1 cm
    # thick from it whose toe ends 1.2 cm from the square opening's side.
    "gusset_bracket": solid(
        [
            box([0.20, 0.16, 0.05], transform=at([0, 0, 0.025])),
            box([0.012, 0.16, 0.11], transform=at([-0.094, 0, 0.055])),
            prism_xz([(-0.089, 0.049), (-0.037, 0.049), (-0.089, 0.11)], 0.01),
        ]
    ),
    # A frustum 22 cm across at its foot and 10 cm across its flat top, 7 cm tall: the top
    # leaves 1.2 cm round a square opening's corners.
    "frustum": revolve([[0, 0], [0.11, 0], [0.05, 0.07], [0, 0.07]], sections=96),
    # A disc with 16 teeth 1 cm deep round a 16 cm root circle, 5 cm tall; the opening
    # 2 cm off its centre.
    "gear_disc": gear(16, 0.08, 0.01, 0.05).apply_translation([-0.02, 0, 0]),
    # A block 20 x 18 cm, 6 cm tall, with a V-groove 2 cm deep and 3 cm wide across it, its
    # near edge 1 cm from the square opening's side.
    "vee_block": solid(
        [box([0.20, 0.18, 0.06], transform=at([0, 0, 0.03]))],
        [prism_xz([(0.035, 0.061), (0.065, 0.061), (0.05, 0.04)], 0.20)],
    ),
    # A wedge 22 x 16 cm, 4 cm tall at one end and 9 cm at the other (13 deg): the hole
    # opens on the sloped face, at its middle.
    "sloped_wedge": prism_xz([(-0.11, 0), (0.11, 0), (0.11, 0.09), (-0.11, 0.04)], 0.16),
}
write_bodies(meshes, HERE)
