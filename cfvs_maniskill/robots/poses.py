"""The tool's poses from the robot's drawing: the peg-tip (tcp) frame that inserts into a
hole frame, the flange behind the peg, the wrist camera in the tcp frame. Pure geometry:
the env, the sensor models and the agents all use it."""

from __future__ import annotations

import numpy as np

from cfvs_maniskill import geometry as G
from cfvs_maniskill.constants import PEG_LENGTH
from cfvs_maniskill.robots.mounts import DEFAULT_MOUNT, MOUNTS, Mount


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


def camera_in_tcp(mount: Mount | None = None) -> np.ndarray:
    """The wrist camera's optical centre in the peg-tip (tcp) frame, from the robot's
    drawing: `mount` (default DEFAULT_MOUNT), the nominal one the robot believes."""
    return (mount or MOUNTS[DEFAULT_MOUNT]).in_tcp()[:3, 3]
