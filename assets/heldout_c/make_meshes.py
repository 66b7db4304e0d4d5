"""Writes held-out set C's mesh bodies (run once; the STL files are committed).

    .venv/bin/python assets/heldout_c/make_meshes.py

Written after the rim fit's parallel-planes check, to test it on shapes it
was not developed on: surfaces parallel to the hole's face beside the opening (fins, rails,
a second boss level), a wall, an inclined chamfer. Metres, bottom at z = 0."""

from pathlib import Path

import numpy as np
import trimesh
from trimesh.creation import box, cylinder
from trimesh.transformations import translation_matrix as at

HERE = Path(__file__).parent


def fuse(*parts):
    return trimesh.boolean.union(list(parts), engine="manifold")


def frustum(r_bottom, r_top, z0, z1, sections=64):
    """A cone frustum (a chamfered hub) between heights z0 and z1."""
    a = np.linspace(0, 2 * np.pi, sections, endpoint=False)
    ring = np.column_stack([np.cos(a), np.sin(a)])
    pts = np.vstack(
        [
            np.column_stack([r_bottom * ring, np.full(sections, z0)]),
            np.column_stack([r_top * ring, np.full(sections, z1)]),
        ]
    )
    return trimesh.convex.convex_hull(pts)


meshes = {
    # Three fins 1.6 cm tall, 8 mm thick, the first 1.6 cm beyond the hole's edge.
    "finned_block": fuse(
        box([0.18, 0.14, 0.05], transform=at([0, 0, 0.025])),
        *[box([0.008, 0.14, 0.018], transform=at([x, 0, 0.058])) for x in (0.045, 0.065, 0.085)],
    ),
    # The hole in a 4.8 cm-radius boss on a 7.5 cm one on a plate: two parallel levels.
    "stepped_boss": fuse(
        box([0.22, 0.18, 0.02], transform=at([0, 0, 0.01])),
        cylinder(0.075, 0.022, transform=at([0, 0, 0.03])),
        cylinder(0.048, 0.017, transform=at([0, 0, 0.0475])),
    ),
    # Two rails 2 cm tall, 1.2 cm from the hole's edge on both sides.
    "rail_plate": fuse(
        box([0.20, 0.16, 0.06], transform=at([0, 0, 0.03])),
        *[box([0.20, 0.012, 0.022], transform=at([0, y, 0.07])) for y in (-0.043, 0.043)],
    ),
    # An L bracket: the hole 2.5 cm from an upright wall 10 cm tall.
    "wall_bracket": fuse(
        box([0.18, 0.12, 0.06], transform=at([0, 0, 0.03])),
        box([0.02, 0.12, 0.16], transform=at([0.08, 0, 0.08])),
    ),
    # A hub whose flat top (r 4.5 cm) falls away in a 45 deg chamfer to a wider disc.
    "chamfered_hub": fuse(
        cylinder(0.10, 0.03, transform=at([0, 0, 0.015])),
        frustum(0.075, 0.045, 0.03, 0.06),
    ),
}
for name, mesh in meshes.items():
    assert mesh.is_watertight, name
    mesh.export(HERE / f"{name}.stl")
    print(name, mesh.bounds.round(3).tolist())
