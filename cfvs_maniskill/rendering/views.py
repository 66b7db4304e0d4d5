"""The cameras for people (videos, `render()`), never for agents: a close view that follows
the hole (aimed at every reset) and an overview of the arm, with ManiSkill's lit "default"
shader (the wrist camera keeps the fast "minimal" one)."""

from __future__ import annotations

import numpy as np
import sapien
from mani_skill.sensors.camera import CameraConfig

from cfvs_maniskill import geometry as G

CLOSEUP_CAMERA = "closeup"
OVERVIEW_CAMERA = "overview"
CLOSEUP_PX = 512
CLOSEUP_FOV = 0.75
CLOSEUP_DISTANCE = 0.40
"""The close view: 512 px, 43 deg, 40 cm from the hole's opening (a 30 cm wide view: the
object's top, the peg and the last part of its approach)."""


def human_camera_configs() -> list[CameraConfig]:
    return [
        CameraConfig(
            CLOSEUP_CAMERA,
            pose=sapien.Pose(),
            width=CLOSEUP_PX,
            height=CLOSEUP_PX,
            fov=CLOSEUP_FOV,
            near=0.01,
            far=10,
            shader_pack="default",
        ),
        CameraConfig(
            OVERVIEW_CAMERA,
            pose=sapien.Pose(),
            width=CLOSEUP_PX // 2,
            height=CLOSEUP_PX // 2,
            fov=0.9,
            near=0.01,
            far=10,
            shader_pack="default",
        ),
    ]


def aim_at_hole(cameras: dict, H: np.ndarray) -> None:
    """Aim the cameras (name -> ManiSkill camera) at the hole frame H. The close view looks
    at the opening from above, 55 deg off the hole's axis to the side (across the arm's
    approach, which would block it); the overview frames the arm's base and the hole from
    above that side, so the table, not the sky, is behind the arm."""
    centre, z = H[:3, 3], H[:3, 2]
    out = centre - [0.0, 0.0, centre[2]]  # the base -> hole direction on the table
    side = np.cross([0.0, 0.0, 1.0], out)
    side = side / (np.linalg.norm(side) + 1e-9)
    look = np.cos(np.radians(55)) * z + np.sin(np.radians(55)) * side
    views = {
        CLOSEUP_CAMERA: (centre + CLOSEUP_DISTANCE * look, centre),
        OVERVIEW_CAMERA: (
            0.5 * centre + 0.75 * side + [0.0, 0.0, 0.8],
            0.6 * centre + [0.0, 0.0, 0.1],
        ),
    }
    for name, (eye, target) in views.items():
        cam = cameras.get(name)
        if cam is not None:  # None: the user replaced the render cameras
            cam.camera.set_local_pose(look_at(np.asarray(eye), np.asarray(target)))


def look_at(eye: np.ndarray, target: np.ndarray) -> sapien.Pose:
    """The pose of a SAPIEN camera (x forward, y left, z up) at `eye` looking at `target`,
    up towards world z: ManiSkill's `look_at` on numpy floats, which costs 20x less than
    its torch round trip (every reset aims two cameras)."""
    forward = (target - eye) / np.linalg.norm(target - eye)
    left = np.cross([0.0, 0.0, 1.0], forward)
    left /= np.linalg.norm(left)
    return G.to_pose(G.make(np.column_stack([forward, left, np.cross(forward, left)]), eye))
