"""Writes held-out set G's mesh bodies (run once; the STL files are committed).

    .venv/bin/python assets/heldout_g/make_meshes.py

Written before any episode on them and before the change was
committed: its clean check. Faces and surroundings no earlier set has: the hole in a raised
round boss barely wider than the opening, along a narrow bar, inside an annular groove, beside
a 45 deg bevelled edge, and among four smaller distractor holes. Metres, bottom at z = 0;
every hole at x = y = 0 (the hole itself is cut by the hole library from the .yaml)."""

from pathlib import Path

import numpy as np
from trimesh.creation import box, cylinder
from trimesh.transformations import rotation_matrix
from trimesh.transformations import translation_matrix as at

from cfvs_maniskill.objects.meshes import solid, write_bodies

HERE = Path(__file__).parent


plate = box([0.20, 0.20, 0.05], transform=at([0, 0, 0.025]))
meshes = {
    # A round boss 8 cm across and 2.5 cm tall: its edge 4.6 mm beyond the square
    # opening's corners (4 mm clearance), 15 mm beyond its sides.
    "raised_boss": solid(
        [plate, cylinder(0.040, 0.025, sections=96, transform=at([0, 0, 0.0625]))]
    ),
    # A bar 6.2 cm wide (8 mm of face either side of the opening), 6 cm tall, 24 cm long,
    # standing on its own.
    "narrow_bar": solid([box([0.24, 0.062, 0.06], transform=at([0, 0, 0.03]))]),
    # An annular groove 8 mm wide and 4 mm deep, 1.7 cm beyond the opening's sides.
    "grooved_face": solid(
        [plate],
        [
            solid(
                [cylinder(0.048, 0.008, sections=96, transform=at([0, 0, 0.05]))],
                [cylinder(0.040, 0.010, sections=96, transform=at([0, 0, 0.05]))],
            )
        ],
    ),
    # The face ends 1.2 cm beyond one side of the opening in a 45 deg bevel down to the
    # bottom.
    "bevel_edge": solid(
        [plate],
        [
            box(
                [0.2, 0.24, 0.2],
                transform=at([0.035, 0, 0.05])
                @ rotation_matrix(-np.pi / 4, [0, 1, 0])
                @ at([0.1, 0, 0]),
            )
        ],
    ),
    # Four round holes 1.2 cm across and 2.5 cm deep, 5 cm from the hole's axis.
    "perforated_plate": solid(
        [plate],
        [
            cylinder(0.006, 0.05, sections=48, transform=at([x, y, 0.05]))
            for x, y in [(0.05, 0), (-0.05, 0), (0, 0.05), (0, -0.05)]
        ],
    ),
}
write_bodies(meshes, HERE)
