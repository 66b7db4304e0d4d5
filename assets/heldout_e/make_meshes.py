"""Writes held-out set E's mesh bodies (run once; the STL files are committed).

    .venv/bin/python assets/heldout_e/make_meshes.py

Written before the change (the convex parts
clipped out of the hole's clearance) and before any episode on them: the clean check of
it. Shape families no earlier set has: a cross, gussets, a counterbore, a tilted top face,
a channel. Metres, bottom at z = 0."""

from pathlib import Path

import numpy as np
import trimesh
from trimesh.creation import box, cylinder
from trimesh.transformations import translation_matrix as at

from cfvs_maniskill.objects.meshes import solid, write_bodies

HERE = Path(__file__).parent
TILT = np.radians(15.0)
"""The tilted column's top face: this far from level, about y."""


def gusset(x):
    """A triangular gusset 8 mm thick at `x`, from the wall (y 0.06) out to y 0.0."""
    pts = [
        [x + dx, y, z]
        for dx in (-0.004, 0.004)
        for y, z in ((0.06, 0.05), (0.06, 0.11), (0.0, 0.05))
    ]
    return trimesh.convex.convex_hull(np.array(pts))


def tilted_column():
    """A 6 cm-radius column whose top is cut by a plane TILT from level through z 0.085."""
    column = cylinder(0.06, 0.14, sections=96, transform=at([0, 0, 0.07]))
    cutter = box([0.4, 0.4, 0.2])
    turn = trimesh.transformations.rotation_matrix(TILT, [0, 1, 0])
    # The cutter's bottom face on the plane: its centre 0.1 above the origin along the normal.
    normal = turn[:3, :3] @ [0, 0, 1.0]
    place = at(np.array([0, 0, 0.085]) + 0.1 * normal) @ turn
    cutter.apply_transform(place)
    return solid([column], [cutter])


meshes = {
    # A plus-shaped body, arms 9 cm wide and 22 cm long, the hole where they cross.
    "cross_hub": solid(
        [
            box([0.22, 0.09, 0.06], transform=at([0, 0, 0.03])),
            box([0.09, 0.22, 0.06], transform=at([0, 0, 0.03])),
        ]
    ),
    # A plate with a wall behind the hole and two triangular gussets 5 cm either side of it.
    "gusset_plate": solid(
        [
            box([0.20, 0.18, 0.05], transform=at([0, 0, 0.025])),
            box([0.20, 0.015, 0.06], transform=at([0, 0.0675, 0.08])),
            gusset(-0.05),
            gusset(0.05),
        ]
    ),
    # A plate with a round counterbore 4.5 cm in radius and 6 mm deep; the hole opens on its floor.
    "counterbore_plate": solid(
        [box([0.18, 0.18, 0.065], transform=at([0, 0, 0.0325]))],
        [cylinder(0.045, 0.02, sections=96, transform=at([0, 0, 0.069]))],
    ),
    # A round column with its top face tilted 15 deg; the hole square to that face.
    "tilted_column": tilted_column(),
    # A channel: two walls 3.5 cm tall, 8.8 cm apart, the hole on its floor between them.
    "u_channel": solid(
        [
            box([0.22, 0.14, 0.05], transform=at([0, 0, 0.025])),
            box([0.22, 0.012, 0.035], transform=at([0, 0.05, 0.0675])),
            box([0.22, 0.012, 0.035], transform=at([0, -0.05, 0.0675])),
        ]
    ),
}
write_bodies(meshes, HERE)
