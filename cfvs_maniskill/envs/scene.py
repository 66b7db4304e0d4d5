"""A task's scenes and its score, as plain geometry: where the hole object and the peg's
start are drawn, and whether a peg pose in the hole's frame counts as inserted."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from cfvs_maniskill import geometry as G
from cfvs_maniskill.constants import (
    PEG_LENGTH,
    PRE_INSERT_HEIGHT,
    SUCCESS_TILT_MARGIN_DEG,
    SUCCESS_TIP_TOLERANCE,
    SUCCESS_WALL_PENETRATION,
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


def wall_penetration(cfg: TaskConfig, tip_in_hole: np.ndarray) -> float:
    """How far the peg's full section is inside the hole's body, m, where it is below the
    opening: a point past the wall is as deep in the body as the nearer of the wall and the
    face round the opening (negative: the free play left; -inf: no full section below the
    opening). Sampled every millimetre along the peg."""
    R, tip = tip_in_hole[:3, :3], tip_in_hole[:3, 3]
    down = R[:, 2]  # the peg's axis, from the flange to the tip
    if down[2] > -1e-6:
        return float("inf")  # the peg points away from the hole's bottom
    lo = cfg.peg_chamfer  # distance from the tip along the peg: its full section starts here
    hi = min(tip[2] / down[2], PEG_LENGTH)  # the section at the opening's plane
    if hi < lo:
        return float("-inf")
    half = peg_half_extent(cfg.peg)
    if cfg.peg == "square":  # the section's corners: its farthest points from the axis
        ring = half * np.array([[1, 1], [1, -1], [-1, 1], [-1, -1]], dtype=float)
    else:
        a = np.linspace(0, 2 * np.pi, 64, endpoint=False)
        ring = half * np.c_[np.cos(a), np.sin(a)]
    along = np.linspace(lo, hi, max(2, int((hi - lo) / 0.001) + 2))
    centres = tip - np.outer(along, down)
    pts = (centres[:, None, :] + (ring @ R[:, :2].T)[None]).reshape(-1, 3)
    reach = np.max(np.abs(pts[:, :2]), axis=1) if cfg.peg == "square" else np.hypot(*pts[:, :2].T)
    past = reach - hole_half_extent(cfg.peg, cfg.clearance)
    inside = np.where(past > 0, np.minimum(past, np.maximum(-pts[:, 2], 0.0)), past)
    return float(inside.max())


def max_tilt_deg(cfg: TaskConfig) -> float:
    """The largest tilt a peg whose section is inside the hole down to its bottom can have:
    the clearance across the hole's depth."""
    return float(np.degrees(np.arctan2(cfg.clearance, cfg.hole_depth)))


def success_tilt_deg(cfg: TaskConfig) -> float:
    """The tilt a success may have: `max_tilt_deg` and a margin."""
    return max_tilt_deg(cfg) + SUCCESS_TILT_MARGIN_DEG


def score(cfg: TaskConfig, tip_in_hole: np.ndarray) -> dict[str, float | bool]:
    """The task's success test on the peg tip's pose in the hole frame: the tip within the
    tolerance of the bottom, the peg's section inside the hole's walls (with the measured
    penetration of the simulated contacts as slack), its axis within the tilt the hole's
    clearance and depth allow plus a margin."""
    tip = tip_in_hole[:3, 3]
    finite = bool(np.all(np.isfinite(tip_in_hole)))
    lateral = float(np.hypot(tip[0], tip[1]))
    tip_to_bottom = float(tip[2] + cfg.hole_depth)
    tilt = float(np.degrees(np.arccos(np.clip(-tip_in_hole[2, 2], -1, 1))))
    penetration = wall_penetration(cfg, tip_in_hole) if finite else float("inf")
    success = (
        abs(tip_to_bottom) <= SUCCESS_TIP_TOLERANCE
        and penetration <= SUCCESS_WALL_PENETRATION
        and tilt <= success_tilt_deg(cfg)
    )
    return dict(
        success=bool(success and finite),
        finite=finite,
        tip_to_bottom=tip_to_bottom,
        lateral_offset=lateral,
        tilt_error_deg=tilt,
        tip_depth=float(-tip[2]),
        wall_penetration=penetration,
    )
