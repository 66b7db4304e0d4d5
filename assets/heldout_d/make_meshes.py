"""Writes held-out set D's mesh bodies (run once; the STL files are committed).

    .venv/bin/python assets/heldout_d/make_meshes.py

Written after the changes to the rim fit (the parallel-planes check, the
ring that follows a square opening), before any episode on them: the clean check of those
changes. Metres, bottom at z = 0."""

from pathlib import Path

import numpy as np
import trimesh
from trimesh.creation import box, cylinder
from trimesh.transformations import translation_matrix as at

from cfvs_maniskill.objects.meshes import solid, write_bodies

HERE = Path(__file__).parent


def prism(radius, sides, height, z0):
    """An upright regular prism (a hexagonal boss when sides = 6)."""
    a = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    ring = radius * np.column_stack([np.cos(a), np.sin(a)])
    pts = np.vstack([np.column_stack([ring, np.full(sides, z)]) for z in (z0, z0 + height)])
    return trimesh.convex.convex_hull(pts)


meshes = {
    # A groove 1.5 cm wide and 1 cm deep, 1.2 cm beyond the hole's edge.
    "slotted_plate": solid(
        [box([0.20, 0.16, 0.06], transform=at([0, 0, 0.03]))],
        [box([0.015, 0.20, 0.02], transform=at([0.0445, 0, 0.06]))],
    ),
    # Two round bosses side by side on a plate, the hole in one.
    "twin_boss": solid(
        [
            box([0.26, 0.14, 0.02], transform=at([0.04, 0, 0.01])),
            cylinder(0.05, 0.04, transform=at([0, 0, 0.04])),
            cylinder(0.04, 0.04, transform=at([0.11, 0, 0.04])),
        ]
    ),
    # A flat ledge with a 30 deg roof rising from 1.5 cm beyond the hole's edge.
    "sloped_ledge": solid(
        [
            box([0.20, 0.14, 0.06], transform=at([0, 0, 0.03])),
            trimesh.convex.convex_hull(
                np.array(
                    [[x, y, z] for x in (0.04, 0.10) for y in (-0.07, 0.07) for z in (0.059, 0.06)]
                    + [[0.10, y, 0.06 + 0.06 * np.tan(np.radians(30))] for y in (-0.07, 0.07)]
                )
            ),
        ]
    ),
    # The hole in the top of a 5 cm-radius flange pipe 9 cm tall, its flange 4 cm down.
    "flange_pipe": solid(
        [
            cylinder(0.05, 0.09, transform=at([0, 0, 0.045])),
            cylinder(0.08, 0.012, transform=at([0, 0, 0.044])),
        ]
    ),
    # A hexagonal boss (across flats 9.5 cm) on a square plate.
    "hex_boss": solid(
        [box([0.20, 0.20, 0.025], transform=at([0, 0, 0.0125])), prism(0.055, 6, 0.04, 0.024)]
    ),
}
write_bodies(meshes, HERE)
