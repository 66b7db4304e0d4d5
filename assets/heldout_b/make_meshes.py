"""Writes held-out set B's mesh bodies (run once; the STL files are committed).

    .venv/bin/python assets/heldout_b/make_meshes.py

Made after the featured procedural generator, from shape families it never draws: a boss,
a pocket, a T, a ramp, a ribbed disc. Metres, bottom at z = 0."""

from pathlib import Path

import numpy as np
import trimesh

HERE = Path(__file__).parent


def box(size, centre, yaw=0.0):
    m = trimesh.creation.box(extents=size)
    m.apply_transform(trimesh.transformations.rotation_matrix(yaw, [0, 0, 1]))
    m.apply_translation(centre)
    return m


def cylinder(radius, height, centre, sections=64):
    return trimesh.creation.cylinder(
        radius, height, sections, transform=trimesh.transformations.translation_matrix(centre)
    )


def union(*parts):
    return trimesh.boolean.union(list(parts), engine="manifold")


def difference(a, *b):
    return trimesh.boolean.difference([a, *b], engine="manifold")


# A round boss (r 4.5 cm, 3 cm tall) on a 20 x 16 cm plate: the hole's face is an island.
boss = union(box([0.20, 0.16, 0.03], [0, 0, 0.015]), cylinder(0.045, 0.032, [0.02, 0, 0.044]))
# A block with a 10 x 10 cm pocket 1.2 cm deep: the hole opens on the pocket's floor.
pocket = difference(box([0.16, 0.16, 0.07], [0, 0, 0.035]), box([0.10, 0.10, 0.05], [0, 0, 0.083]))
# A T: a 20 x 7 cm bar on a 7 x 12 cm stem; the hole where they meet.
t_block = union(
    box([0.20, 0.07, 0.055], [0, 0.035, 0.0275]), box([0.07, 0.12, 0.055], [0, -0.06, 0.0275])
)
# A ramp rising from the hole's face to 4 cm beside it.
ramp = trimesh.convex.convex_hull(
    np.array(
        [
            [0.03, -0.07, 0.06],
            [0.03, 0.07, 0.06],
            [0.09, -0.07, 0.10],
            [0.09, 0.07, 0.10],
            [0.03, -0.07, 0.0],
            [0.03, 0.07, 0.0],
            [0.09, -0.07, 0.0],
            [0.09, 0.07, 0.0],
        ]
    )
)
ramp_block = union(box([0.16, 0.14, 0.06], [-0.03, 0, 0.03]), ramp)
# A disc with two crossing ribs (1.5 cm wide, 2 cm tall) passing 1 cm from the hole.
ribbed = union(
    cylinder(0.11, 0.05, [0, 0, 0.025]),
    box([0.22, 0.015, 0.022], [0, 0.045, 0.06]),
    box([0.015, 0.22, 0.022], [0.045, 0, 0.06]),
)
meshes = {
    "boss_plate": boss,
    "pocket_block": pocket,
    "t_block": t_block,
    "ramp_block": ramp_block,
    "ribbed_disc": ribbed,
}
for name, mesh in meshes.items():
    assert mesh.is_watertight, name
    mesh.export(HERE / f"{name}.stl")
    print(name, mesh.bounds.round(3).tolist())
