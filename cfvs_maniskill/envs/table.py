"""The table the hole objects stand on: a 2 x 2 m slab whose top is the world's z = 0."""

from __future__ import annotations

import sapien

TABLE_COLOR = (0.82, 0.8, 0.76)
"""A light wooden bench top (its texture for the stereo camera: sensing/surfaces.py)."""


def build_table(scene):
    b = scene.create_actor_builder()
    b.add_box_collision(half_size=[1.0, 1.0, 0.025])
    b.add_box_visual(
        half_size=[1.0, 1.0, 0.025],
        material=sapien.render.RenderMaterial(base_color=[*TABLE_COLOR, 1.0]),
    )
    b.initial_pose = sapien.Pose(p=[0.3, 0, -0.025])
    return b.build_static(name="table")
