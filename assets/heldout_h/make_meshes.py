"""Writes held-out set H's mesh bodies (run once; the STL files are committed).

    .venv/bin/python assets/heldout_h/make_meshes.py

Written before any episode on them and before the change
was committed: its clean check. Other surfaces beside the opening at other levels and other
openings: a second square hole of the same size 3.5 cm away, tiers stepping up on one
side and down on the other, a rib across at 30 deg, a sunken floor inside a frame, two
shallow slots either side. Metres, bottom at z = 0; every hole at x = y = 0 (the hole
itself is cut by the hole library from the .yaml)."""

from pathlib import Path

import numpy as np
from trimesh.creation import box
from trimesh.transformations import rotation_matrix
from trimesh.transformations import translation_matrix as at

from cfvs_maniskill.objects.meshes import solid, write_bodies

HERE = Path(__file__).parent


meshes = {
    # A second square opening 5 cm wide and 4.5 cm deep, its side 3.5 cm from the hole's.
    "twin_holes": solid(
        [box([0.26, 0.16, 0.05], transform=at([0.04, 0, 0.025]))],
        [box([0.05, 0.05, 0.045], transform=at([0.085, 0, 0.0276]))],
    ),
    # A tier 3 cm up on one side and one 2 cm down on the other, each 2 cm from the
    # opening's side.
    "tiered_block": solid(
        [
            box([0.20, 0.14, 0.05], transform=at([0, 0, 0.025])),
            box([0.055, 0.14, 0.03], transform=at([0.0725, 0, 0.065])),
        ],
        [box([0.06, 0.16, 0.021], transform=at([-0.075, 0, 0.0405]))],
    ),
    # A rib 1.2 cm wide and 1.5 cm tall crossing the face at 30 deg, 4.4 cm from the axis.
    "angled_rib": solid(
        [
            box([0.20, 0.20, 0.05], transform=at([0, 0, 0.025])),
            box(
                [0.24, 0.012, 0.015],
                transform=rotation_matrix(np.pi / 6, [0, 0, 1]) @ at([0, 0.05, 0.0575]),
            ),
        ]
    ),
    # The hole on a floor 2 cm below a frame: a pocket 12 cm square.
    "sunken_plate": solid(
        [box([0.22, 0.22, 0.07], transform=at([0, 0, 0.035]))],
        [box([0.12, 0.12, 0.021], transform=at([0, 0, 0.0605]))],
    ),
    # Two slots 6 mm wide and 3 mm deep either side, 7 mm beyond the opening's sides.
    "slotted_face": solid(
        [box([0.20, 0.20, 0.05], transform=at([0, 0, 0.025]))],
        [box([0.22, 0.006, 0.0061], transform=at([0, s * 0.035, 0.05])) for s in (1, -1)],
    ),
}
write_bodies(meshes, HERE)
