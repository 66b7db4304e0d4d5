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

from cfvs_maniskill import geometry as G
from cfvs_maniskill.constants import PEG_LENGTH


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

    @staticmethod
    def of(task: Any) -> TaskSpec:
        """From a TaskConfig (or anything with these fields)."""
        return TaskSpec(**{f.name: getattr(task, f.name) for f in fields(TaskSpec)})


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


def insertion_pose(peg: str, hole: np.ndarray, depth: float, ref: np.ndarray) -> np.ndarray:
    """Tcp pose with the tip `depth` m below the opening of the hole frame `hole` (negative:
    above it), pointing into the hole. For a square peg the tool's x is the hole axis
    (x, y, -x, -y) nearest to `ref`'s x (the current tool), so the wrist never turns more
    than 45 deg; a round peg keeps `ref`'s x."""
    z = -hole[:3, 2]
    x_hint = ref[:3, 0]
    if peg == "square":
        cands = [hole[:3, 0], hole[:3, 1], -hole[:3, 0], -hole[:3, 1]]
        x_hint = max(cands, key=lambda c: float(c @ x_hint))
    return G.make(G.frame_with_z(z, x_hint), hole[:3, 3] + depth * z)


def flange_pose(tcp: np.ndarray) -> np.ndarray:
    """The flange's (tool0's) 4x4 pose from the peg tip frame's: PEG_LENGTH back along the
    tool axis (the peg is rigid on the flange, same axes)."""
    T = np.array(tcp, dtype=np.float64, copy=True)
    T[:3, 3] -= PEG_LENGTH * T[:3, 2]
    return T


def camera_in_tcp() -> np.ndarray:
    """The wrist camera's optical centre in the peg-tip (tcp) frame, from the robot's
    drawing (its nominal mount: the calibration the robot believes, not the true one)."""
    from cfvs_maniskill.robots.ur5 import CAMERA_OFFSET

    return np.asarray(CAMERA_OFFSET, dtype=np.float64) - np.array([0.0, 0.0, PEG_LENGTH])
