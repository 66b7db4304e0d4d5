"""Self-calibration against the table: the robot knows its table is the plane z = 0, so the
plane its wrist camera reports there measures the camera's own errors.

A depth-scale error s moves every point along its ray, p -> s p in the camera's frame; a
hand-eye rotation error turns the whole cloud about the camera. Seen on the table, the first
tilts nothing and puts the plane at s times its distance from the camera; the second tilts
the plane's normal (two of its three angles: a turn about the normal leaves a plane as it
is). The correction undoes both about the camera, in the camera's frame, so one measured
where much of the table is in view (the coarse view) holds at every later pose of the
episode: the errors are fixed to the camera. What the table cannot tell: the hand-eye
translation (its component along the normal is taken as scale, exact at the table's depth)
and the turn about the normal.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from cfvs_maniskill import geometry as G
from cfvs_maniskill.perception.clouds import fit_table

MIN_TABLE_POINTS = 2000
"""Fewer table points than this measure the plane too poorly to calibrate against."""
MAX_SCALE_ERROR = 0.05
"""A plane further off its known height than this fraction of its distance is not the table
(a large flat face of the part, near the table's height): no correction."""
MAX_TILT_DEG = 3.0
"""... nor one tilted more than this (hand-eye calibrations are good to a degree or so)."""


@dataclass(frozen=True)
class CameraCorrection:
    """True camera-frame points = scale * rotation @ reported ones (rotation in the camera
    frame of whichever pose the cloud was taken from)."""

    rotation: np.ndarray
    scale: float

    def apply(self, world: np.ndarray, camera: np.ndarray) -> np.ndarray:
        """World points (K, 3) as reported by a camera at 4x4 pose `camera` (its believed
        pose) -> where the correction puts them."""
        R, c = camera[:3, :3], camera[:3, 3]
        M = self.scale * R @ self.rotation @ R.T
        return ((world - c) @ M.T + c).astype(np.float32)

    @property
    def tilt_deg(self) -> float:
        return float(np.degrees(Rotation.from_matrix(self.rotation).magnitude()))


IDENTITY = CameraCorrection(np.eye(3), 1.0)


def correction_from_table(
    world: np.ndarray, camera: np.ndarray, table_height: float = 0.0
) -> CameraCorrection | None:
    """The correction that puts the table a cloud shows at its known height with its normal
    up, from the cloud's world points that saw something (`valid_world_points`) taken by a
    camera believed at 4x4 `camera`; None when too little table is in view or the plane
    found is too far off to be the table's."""
    table = fit_table(world, min_points=MIN_TABLE_POINTS)
    if np.count_nonzero(np.abs(table.height(world)) < table.margin) < MIN_TABLE_POINTS:
        return None
    c = camera[:3, 3].astype(np.float64)
    up = np.array([0.0, 0.0, 1.0])
    n = np.asarray(table.normal, np.float64)
    reported = float(n @ c - table.offset)  # the camera's distance from the plane it sees
    known = float(c[2] - table_height)
    if reported <= 0 or known <= 0 or abs(known / reported - 1.0) > MAX_SCALE_ERROR:
        return None
    if G.angle_deg(n, up) > MAX_TILT_DEG:
        return None
    turn = G.shortest_turns(n, up)  # the world turn taking the reported normal up ...
    R = camera[:3, :3].astype(np.float64)  # ... in the camera's frame
    return CameraCorrection(R.T @ turn @ R, known / reported)
