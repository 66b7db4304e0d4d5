"""KOVIS's dataset (the KOVIS baseline), drawn by `python -m cfvs_maniskill.data collect
--kind kovis`: rollouts as KOVIS's own data generator makes them: from the pre-insertion
pose, 5 steps along a random direction (within the task's degrees of freedom) of one random
length; at each pose the wrist camera's stereo pair of grey images, their depth and
segmentation (the decoder's targets), and the tool-frame motion (dt, dtheta) back to the
pre-insertion pose."""

from __future__ import annotations

import json

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from cfvs_maniskill import geometry as G
from cfvs_maniskill.constants import PRE_INSERT_HEIGHT
from cfvs_maniskill.perception import labels as L
from cfvs_maniskill.policies.dataset import SampleKind
from cfvs_maniskill.policies.kovis.agent import MOUNT
from cfvs_maniskill.policies.kovis.model import KOVISConfig

ROLLOUT_FRAMES = 5
"""Frames per rollout (KOVIS's rollout_step)."""
ROLLOUT_STEP = (0.001, 0.07)
"""Rollout step range, m, drawn log-uniformly (KOVIS's steps are 1-17 mm; ours reach 28 cm in
four steps: the task starts 15-30 cm away)."""
STEREO_BASELINE_RANGE = (0.015, 0.06)
"""KOVIS randomises the stereo baseline (40-60 mm); ours spans the profiles' imagers too
(the D405's 18 mm, the D435's 50 mm)."""
IMAGER_JITTER = (0.005, 2.0)
"""KOVIS randomises the camera pose per image: up to this many m / deg here."""
KOVIS_TARGET_SIZE = KOVISConfig.heatmap
"""Side of the decoder's depth / segmentation targets."""
ROTATION_SCALE = KOVISConfig.rot_mul
"""KOVIS's rot_mul: a unit rollout motion turns this many rad per metre travelled."""


def _rollout(args, task, u, obs, H, rng, i):
    """One KOVIS rollout: from the pre-insertion pose (the goal) the tool moves along a
    random direction for ROLLOUT_FRAMES steps of one random length (KOVIS's oja_insert:
    5 steps of a random velocity for a random time step); every pose's stereo pair,
    with its depth and segmentation, is labelled with the motion back to the goal."""
    from cfvs_maniskill.perception.images import (
        SEG_HOLE,
        SEG_PEG,
        stereo_images,
        stereo_targets,
    )
    from cfvs_maniskill.task_dof import constrain

    start = u.tcp_matrix()
    goal = constrain(task, u.insertion_pose(-PRE_INSERT_HEIGHT, H, start), ref=start)
    seg_ids = {
        int(u.agent.robot.links_map["peg"].per_scene_id[0]): SEG_PEG,
        int(u.hole_objects[u.object_index].per_scene_id[0]): SEG_HOLE,
    }
    q_seed = u.agent.robot.get_qpos()[0].numpy()
    for _ in range(20):
        twist = _rollout_direction(rng, task, goal, H)
        # KOVIS's time steps (1-17 mm per step at unit speed) reach 8.5 cm; ours also
        # cover the task's 15-30 cm starts (default: two thirds within KOVIS's range).
        step = float(np.exp(rng.uniform(*np.log(args.rollout_step))))
        frames = []
        for k in range(ROLLOUT_FRAMES):
            a = twist * step * k  # goal = pose @ D(a)
            pose = goal @ G.inv(L.apply_action(np.eye(4), _to_rotation(a)))
            if (G.inv(H) @ pose)[2, 3] < 0.005:
                break  # the tip would be inside the object (KOVIS stops at contact)
            q, ok = u.ik(pose, q_seed)
            if not ok:
                break
            frames.append(q)
            q_seed = q
        if len(frames) >= 3:  # KOVIS redraws rollouts shorter than this
            break
    else:
        return None
    baseline = float(rng.uniform(*STEREO_BASELINE_RANGE))
    rows = {k: [] for k in ("images", "depth", "seg", "twist", "tcp_pose")}
    for k in range(ROLLOUT_FRAMES):
        q = frames[min(k, len(frames) - 1)]  # short rollouts repeat their last frame
        u.agent.reset(torch.as_tensor(q, dtype=torch.float32)[None])
        _jitter_imagers(u, rng, baseline)
        obs = u.get_obs()
        tcp = u.tcp_matrix()
        rows["images"].append(stereo_images(obs))
        d, sg = stereo_targets(obs, seg_ids, KOVIS_TARGET_SIZE)
        rows["depth"].append(d)
        rows["seg"].append(sg)
        rows["twist"].append(L.fine_action(tcp, goal))  # (dt, dr): goal = tcp @ D
        rows["tcp_pose"].append(tcp)
    out = {k: np.stack(v) for k, v in rows.items()}
    out["twist"] = out["twist"].astype(np.float32)
    out.update(
        valid=np.arange(ROLLOUT_FRAMES) < len(frames),
        baseline=np.array(baseline, dtype=np.float32),
        hole_pose=H,
        target_pose=goal,
        object=np.array(u.episode_info["object"]),
        sample_index=np.array(i, dtype=np.int64),
    )
    return out


def _rollout_direction(rng, task, goal: np.ndarray, H: np.ndarray) -> np.ndarray:
    """A unit motion (v, w) in the tool frame, w in KOVIS's rotation units (rad / rot_mul),
    within the task's degrees of freedom. Half the translations lie in the cone the task's
    starts come from (widened by 20 deg), half anywhere: the servo strays off that cone."""
    if rng.uniform() < 0.5:
        v = G.random_cone(rng, H[:3, 2], np.radians(task.init_cone_deg + 20.0))
    else:
        v = rng.normal(size=3)
    v = goal[:3, :3].T @ (v / np.linalg.norm(v))  # world -> tool frame
    w = np.zeros(3)
    if task.dof == 4:
        w[2] = rng.uniform(-1, 1)
    elif task.dof == 6:
        w = rng.uniform(-1, 1, 3)
    m = np.concatenate([v * rng.uniform(0.5, 1.0) if task.dof > 3 else v, w])
    return m / np.linalg.norm(m)


def _to_rotation(m: np.ndarray) -> np.ndarray:
    """KOVIS units (rotation / rot_mul) -> a tool-frame action (dt, dr in radians)."""
    a = np.array(m, dtype=np.float64)
    a[3:] *= ROTATION_SCALE
    return a


def _jitter_imagers(u, rng, baseline: float) -> None:
    """Move both stereo imagers by one random small rigid offset (KOVIS's camera pose
    randomisation) and set this rollout's baseline."""
    import sapien

    from cfvs_maniskill.robots.ur5 import STEREO_UIDS, camera_pose_in_tool

    t, deg = IMAGER_JITTER
    d = rng.normal(size=3)
    r = rng.normal(size=3)
    jitter = G.make(
        Rotation.from_rotvec(r / np.linalg.norm(r) * np.radians(rng.uniform(0, deg))).as_matrix(),
        d / np.linalg.norm(d) * rng.uniform(0, t),
    )
    left = camera_pose_in_tool() * G.to_pose(jitter)
    for uid, offset in zip(STEREO_UIDS, (0.0, baseline), strict=True):
        pose = left * sapien.Pose(p=[0.0, -offset, 0.0])
        u.scene.sensors[uid].camera.set_local_pose(pose)


def _check(args) -> None:
    if not 0 < args.rollout_step[0] <= args.rollout_step[1] <= 0.1:
        raise ValueError(
            f"--rollout-step: expected 0 < MIN <= MAX <= 0.1 m, got {args.rollout_step}"
        )


def _attrs(args) -> dict:
    # Only when not the default, so files collected before the option still resume.
    if tuple(args.rollout_step) != ROLLOUT_STEP:
        return {"rollout_step": json.dumps(list(args.rollout_step))}
    return {}


KINDS = {
    "kovis": SampleKind(
        # The stereo imagers, and segmentation for the decoder's targets.
        {"obs_mode": "rgb+depth+segmentation", "stereo": True, "camera_mount": MOUNT},
        True,
        _rollout,
        check=_check,
        attrs=_attrs,
    )
}
"""KOVIS's rollouts (images + motion to the goal)."""
