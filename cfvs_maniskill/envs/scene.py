"""A task's scenes and its score, as plain geometry: where the hole object and the peg's
start are drawn, and whether a peg pose in the hole's frame counts as inserted."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from cfvs_maniskill import geometry as G
from cfvs_maniskill.constants import (
    PRE_INSERT_HEIGHT,
    SUCCESS_LATERAL_MARGIN,
    SUCCESS_MAX_TILT_DEG,
    SUCCESS_TIP_TOLERANCE,
    hole_half_extent,
    peg_half_extent,
)
from cfvs_maniskill.envs.task_config import TaskConfig
from cfvs_maniskill.robots.poses import insertion_pose
from cfvs_maniskill.robots.ur5 import start_seeds


def sample_object_pose(
    rng: np.random.Generator, cfg: TaskConfig, geom
) -> tuple[np.ndarray, np.ndarray]:
    """The hole object's world pose on the table and its hole frame: yaw, tilt about a
    random horizontal axis, a place in the workspace, the lowest point on the table."""
    yaw = np.radians(rng.uniform(*cfg.yaw_deg))
    tilt = np.radians(rng.uniform(*cfg.tilt_deg))
    azimuth = rng.uniform(0, 2 * np.pi)
    axis = np.array([np.cos(azimuth), np.sin(azimuth), 0.0])
    R = (Rotation.from_rotvec(axis * tilt) * Rotation.from_euler("z", yaw)).as_matrix()
    v = geom.visual_vertices @ R.T
    xy = [rng.uniform(*cfg.workspace_x), rng.uniform(*cfg.workspace_y)]
    T_obj = G.make(R, np.array([*xy, -v[:, 2].min()]))
    return T_obj, T_obj @ G.make(np.eye(3), geom.hole_frame)


def sample_start(
    rng: np.random.Generator, cfg: TaskConfig, H: np.ndarray, distance: float
) -> np.ndarray:
    """The peg tip's start pose: `distance` from the hole's centre within the task's cone
    about its axis, aimed at it within init_aim_deg, rolled within init_roll_deg."""
    while True:
        u = G.random_cone(rng, H[:3, 2], np.radians(cfg.init_cone_deg))
        if u[2] > 0.5:  # start above the hole, never below the table's horizon
            break
    p = H[:3, 3] + distance * u
    look = G.random_cone(rng, -u, np.radians(cfg.init_aim_deg))
    R = G.frame_with_z(look, np.array([1.0, 0.0, 0.0]))
    roll = np.radians(rng.uniform(-cfg.init_roll_deg, cfg.init_roll_deg))
    c, s = np.cos(roll), np.sin(roll)
    return G.make(R @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]), p)


def solvable_start(
    cfg: TaskConfig, kinematics, collision, T_obj, H, T_start, surface
) -> np.ndarray | None:
    """Joints for the start pose T_start from which the pre-insertion and the inserted pose
    are reachable along one IK branch, with the arm clear of the table and of the object
    (`surface`: points on it, body frame; object pose T_obj, hole frame H) at all three, the
    peg excepted at the last (it is in the hole); None if no branch is."""
    obstacle = surface @ T_obj[:3, :3].T + T_obj[:3, 3]
    tree = cKDTree(obstacle)
    for seed in start_seeds(T_start):
        q0, ok0 = kinematics.ik(T_start, seed)
        q1, ok1 = kinematics.ik(insertion_pose(cfg.peg, H, -PRE_INSERT_HEIGHT, T_start), q0)
        q2, ok2 = kinematics.ik(insertion_pose(cfg.peg, H, cfg.hole_depth - 0.002, T_start), q1)
        if not (ok0 and ok1 and ok2):
            continue
        checks = ((q0, ()), (q1, ()), (q2, ("peg",)))
        if all(collision.touches(q, obstacle, tree, 0.0, skip=skip) is None for q, skip in checks):
            return q0
    return None


def score(cfg: TaskConfig, tip_in_hole: np.ndarray) -> dict[str, float | bool]:
    """The task's success test on the peg tip's pose in the hole frame: the tip within the
    tolerance of the bottom, inside the cross-section, the axis within the tilt limit."""
    tip = tip_in_hole[:3, 3]
    lateral = float(np.hypot(tip[0], tip[1]))
    tip_to_bottom = float(tip[2] + cfg.hole_depth)
    tilt = float(np.degrees(np.arccos(np.clip(-tip_in_hole[2, 2], -1, 1))))
    room = hole_half_extent(cfg.peg, cfg.clearance) - peg_half_extent(cfg.peg)
    inside = (
        lateral <= room * np.sqrt(2) + SUCCESS_LATERAL_MARGIN
        and max(abs(tip[0]), abs(tip[1])) <= room + SUCCESS_LATERAL_MARGIN
    )
    finite = bool(np.all(np.isfinite(tip_in_hole)))
    success = (
        abs(tip_to_bottom) <= SUCCESS_TIP_TOLERANCE and inside and tilt <= SUCCESS_MAX_TILT_DEG
    )
    return dict(
        success=bool(success and finite),
        finite=finite,
        tip_to_bottom=tip_to_bottom,
        lateral_offset=lateral,
        tilt_error_deg=tilt,
        tip_depth=float(-tip[2]),
    )
