"""Writes held-out set F's mesh bodies (run once; the STL files are committed).

    .venv/bin/python assets/heldout_f/make_meshes.py

Written before the change (the approach yaw chosen
for a clear view) and before any episode on them: the clean check of it. Tall things
beside the hole, in directions no earlier set has (two walls in a corner, a post, a deep
slot, a tower off the diagonal) and a ledge stepping up beside the opening. Metres, bottom
at z = 0; every hole at x = y = 0."""

from pathlib import Path

from trimesh.creation import box, cylinder
from trimesh.transformations import translation_matrix as at

from cfvs_maniskill.objects.meshes import solid, write_bodies

HERE = Path(__file__).parent


meshes = {
    # Two walls 9 cm tall meeting in a corner, their inner faces 5.5 cm from the hole's axis.
    "corner_walls": solid(
        [
            box([0.20, 0.20, 0.05], transform=at([0, 0, 0.025])),
            box([0.015, 0.20, 0.09], transform=at([0.0625, 0, 0.095])),
            box([0.20, 0.015, 0.09], transform=at([0, 0.0625, 0.095])),
        ]
    ),
    # A round post 5 cm across and 12 cm tall, its side 5 cm from the hole's axis.
    "tall_post": solid(
        [
            box([0.20, 0.18, 0.05], transform=at([0, 0, 0.025])),
            cylinder(0.025, 0.12, sections=64, transform=at([0, 0.075, 0.11])),
        ]
    ),
    # A slot 12 cm wide between walls 8 cm tall; the hole on its floor.
    "deep_slot": solid(
        [
            box([0.22, 0.16, 0.05], transform=at([0, 0, 0.025])),
            box([0.22, 0.02, 0.08], transform=at([0, 0.07, 0.09])),
            box([0.22, 0.02, 0.08], transform=at([0, -0.07, 0.09])),
        ]
    ),
    # A 6 x 6 cm tower 11 cm tall off the hole's diagonal, its near corner 4 cm out on x
    # and 3.5 cm on y.
    "corner_tower": solid(
        [
            box([0.20, 0.20, 0.05], transform=at([0, 0, 0.025])),
            box([0.06, 0.06, 0.11], transform=at([0.07, 0.065, 0.105])),
        ]
    ),
    # A ledge 1.5 cm high whose edge runs 1.2 cm beyond the opening on one side.
    "step_ledge": solid(
        [
            box([0.20, 0.18, 0.05], transform=at([0, 0, 0.025])),
            box([0.063, 0.18, 0.015], transform=at([0.0685, 0, 0.0575])),
        ]
    ),
}
write_bodies(meshes, HERE)
