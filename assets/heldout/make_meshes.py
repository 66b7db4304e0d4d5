"""Writes the held-out mesh bodies (run once; the STL files are committed).

    .venv/bin/python assets/heldout/make_meshes.py

Unions of boxes with manifold3d (through trimesh), metres, bottom at z = 0."""

from pathlib import Path

import trimesh

HERE = Path(__file__).parent


def box(size, centre):
    return trimesh.creation.box(
        extents=size, transform=trimesh.transformations.translation_matrix(centre)
    )


def union(*parts):
    return trimesh.boolean.union(list(parts), engine="manifold")


# L-shaped block: a 16 x 8 cm arm and an 8 x 16 cm arm, 6 cm tall; the hole sits in the
# corner square where the arms meet, 1 cm from the inner corner's walls.
l_block = union(
    box([0.16, 0.08, 0.06], [0.0, -0.04, 0.03]), box([0.08, 0.16, 0.06], [-0.04, 0.0, 0.03])
)
# A base plate with a wall 3 cm high along one side, 1.5 cm from the hole's edge.
walled = union(
    box([0.14, 0.14, 0.06], [0.0, 0.0, 0.03]), box([0.14, 0.02, 0.03], [0.0, 0.05, 0.075])
)
# A stepped block: the hole on the lower step, the upper step (4 cm higher) beside it.
stepped = union(
    box([0.20, 0.12, 0.055], [0.0, 0.0, 0.0275]), box([0.08, 0.12, 0.04], [0.06, 0.0, 0.075])
)
for name, mesh in {"l_block": l_block, "walled_plate": walled, "stepped_block": stepped}.items():
    assert mesh.is_watertight, name
    mesh.export(HERE / f"{name}.stl")
    print(name, mesh.bounds.round(3).tolist())
