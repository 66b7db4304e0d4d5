"""What an agent may know: the task's nominal constants and what a robot's own sensors say.

A real cell gives its controller the wrist camera's output, the joint angles (and the tool
pose by forward kinematics), a wrist force/torque reading and the drawing of the part it
must insert into: peg, nominal hole size and depth, clearance. It never gives the true
hole pose, the object's name, the simulator's step info or per-pixel segmentation. Agents
here are built from a `TaskSpec` (not the env) and act on a `robot_view` of each
observation, so none of that can reach them; only the oracle is handed the env, and the
registry marks it privileged.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np

# The tool's poses from the robot's drawing, part of what an agent may use.
from cfvs_maniskill.robots.mounts import DEFAULT_MOUNT, MOUNTS, Mount
from cfvs_maniskill.robots.poses import camera_in_tcp, flange_pose, insertion_pose

__all__ = [
    "ALLOWED_OBS",
    "TaskSpec",
    "camera_in_tcp",
    "flange_pose",
    "insertion_pose",
    "robot_view",
]


@dataclass(frozen=True)
class TaskSpec:
    """The task's nominal constants (from its file), as a robot program would know them."""

    name: str
    env_id: str
    peg: str
    dof: int
    clearance: float
    peg_chamfer: float
    hole_depth: float
    workspace_x: tuple[float, float]
    workspace_y: tuple[float, float]
    camera_width: int
    camera_height: int
    mount: Mount = MOUNTS[DEFAULT_MOUNT]
    """Where the wrist camera sits on the tool, as drawn (the sensor profile's mount)."""

    @staticmethod
    def of(task: Any, mount: Mount | None = None) -> TaskSpec:
        """From a TaskConfig (or anything with these fields) and the camera's mount."""
        known = {f.name: getattr(task, f.name) for f in fields(TaskSpec) if f.name != "mount"}
        return TaskSpec(**known, mount=mount or MOUNTS[DEFAULT_MOUNT])

    @staticmethod
    def of_env(env: Any) -> TaskSpec:
        """What an agent may know of a made env: its task file and its camera's mount."""
        u = env.unwrapped
        return TaskSpec.of(u.task, u.camera_mount)

    def camera_in_tcp(self) -> np.ndarray:
        """The camera's optical centre in the peg-tip frame, on this task's mount."""
        return camera_in_tcp(self.mount)


ALLOWED_OBS = {
    "pointcloud": {"xyzw", "rgb"},
    "sensor_data": {"rgb", "depth"},
    "stereo_imagers": {"rgb"},
}
"""The observation keys a robot has: the wrist cloud (xyz, colour) or the wrist images (the
stereo imagers' grey views; their depth is the renderer's exact one, which the sensor
profile's depth model never touched, so it is not handed on). Segmentation, the
simulator's `extra` (true poses) and the camera's true extrinsics are not."""


def robot_view(obs: Any) -> dict:
    """The part of a ManiSkill observation a real robot would have (see ALLOWED_OBS)."""
    if not isinstance(obs, dict):
        return {}
    out: dict = {}
    if "pointcloud" in obs:
        out["pointcloud"] = {
            k: v for k, v in obs["pointcloud"].items() if k in ALLOWED_OBS["pointcloud"]
        }
    if "sensor_data" in obs:
        from cfvs_maniskill.robots.ur5 import STEREO_UIDS

        out["sensor_data"] = {
            cam: {
                k: v
                for k, v in data.items()
                if k in ALLOWED_OBS["stereo_imagers" if cam in STEREO_UIDS else "sensor_data"]
            }
            for cam, data in obs["sensor_data"].items()
        }
    return out
