"""CFVS's datasets (paper: Data generation), drawn by `python -m cfvs_maniskill.data collect`.

* coarse: the peg at the task's initial configuration, 15-30 cm (the task's init_error
  range) from a randomly placed hole object; the cloud, keypoints, offsets, confidence.
* fine: the peg at the true pre-insertion pose moved by a random tool-frame offset
  (-dt, -dtheta, ranges from the task file); the cropped cloud and the action (dt, dtheta)
  that undoes it. The robot is set to the perturbed pose directly (no motion is needed to
  render what the camera would see there).
"""

from __future__ import annotations

import numpy as np
import torch

from cfvs_maniskill import geometry as G
from cfvs_maniskill.constants import PRE_INSERT_HEIGHT
from cfvs_maniskill.perception import labels as L
from cfvs_maniskill.perception.clouds import (
    MIN_OBJECT_POINTS,
    fine_crop,
    sample_fixed,
    valid_world_points,
    world_object_points,
    world_to_tool,
)
from cfvs_maniskill.perception.peg import apply as apply_correction
from cfvs_maniskill.perception.peg import peg_correction
from cfvs_maniskill.policies.dataset import SampleKind


def fine_start(u, H: np.ndarray, rng, max_translation: float, constrain=None, tries: int = 50):
    """Joints putting the tool at a random fine-stage error from the true pre-insertion pose
    (the paper's "-dt, -dtheta"; tilt and yaw within the task's limits, `constrain(T, T0)`
    keeps the task's DoF): the first of `tries` draws the arm reaches with the tip still
    out of the object; None if none is."""
    task = u.task
    q_seed = u.agent.robot.get_qpos()[0].numpy()
    T0 = u.insertion_pose(-PRE_INSERT_HEIGHT, H)
    for _ in range(tries):
        offset = L.random_offset(
            rng, max_translation, task.fine_max_tilt_deg, task.fine_max_yaw_deg
        )
        Tp = T0 @ G.inv(offset)
        if constrain is not None:
            Tp = constrain(Tp, T0)
        if (G.inv(H) @ Tp)[2, 3] < 0.005:
            continue  # the tip would be inside the object: not a pose the servo visits
        q, ok = u.ik(Tp, q_seed)
        if ok:
            return q
    return None


def seen_object_points(task, obs, tcp: np.ndarray) -> np.ndarray:
    """Tool-frame object points of a view as the agent reads them: the cloud moved onto the
    peg it shows (as `calibration` does; a camera that does not see the peg leaves it as it is),
    then the table and the peg dropped. Fitted on each view: a sample has only its own."""
    world = valid_world_points(obs["pointcloud"]["xyzw"][0].numpy())
    fix = peg_correction(world, tcp, task.peg, task.peg_chamfer)
    return world_object_points(apply_correction(fix, world, tcp), tcp, task.peg)


def _common(u, points, tcp, H, i):
    return {
        "points": points.astype(np.float32),
        "tcp_pose": tcp,
        "hole_pose": H,
        "object": np.array(u.episode_info["object"]),
        "sample_index": np.array(i, dtype=np.int64),
    }


def _coarse(args, task, u, obs, H, rng, i):
    tcp = u.tcp_matrix()
    pts = seen_object_points(task, obs, tcp)
    if len(pts) < MIN_OBJECT_POINTS:
        return None  # the camera hardly sees the object: redraw
    pts = sample_fixed(pts, args.points, rng)
    k = world_to_tool(L.keypoints_world(H, tcp, task.peg), tcp)
    row = _common(u, pts, tcp, H, i)
    row.update(
        keypoints=k.astype(np.float32),
        offsets=L.offsets(pts, k),
        confidence=L.confidence(pts, k[0]),
        init_error=np.array(np.linalg.norm(tcp[:3, 3] - H[:3, 3]), dtype=np.float32),
    )
    return row


def _fine(args, task, u, obs, H, rng, i):
    q = fine_start(u, H, rng, task.fine_max_translation)
    if q is None:
        return None
    u.agent.reset(torch.as_tensor(q, dtype=torch.float32)[None])
    obs = u.get_obs()
    tcp = u.tcp_matrix()  # what the robot really reached (IK is exact to < 1 mm)
    target = u.insertion_pose(-PRE_INSERT_HEIGHT, H, tcp)
    pts = fine_crop(seen_object_points(task, obs, tcp))
    if len(pts) < MIN_OBJECT_POINTS:
        return None  # the crop sees (almost) nothing: not a useful sample
    pts = sample_fixed(pts, args.points, rng)
    row = _common(u, pts, tcp, H, i)
    row.update(action=L.fine_action(tcp, target), target_pose=target)
    return row


KINDS = {
    "coarse": SampleKind({"obs_mode": "pointcloud"}, False, _coarse),
    "fine": SampleKind({"obs_mode": "pointcloud"}, True, _fine),
}
"""OAKN's (keypoints + confidence) and OPN's (actions) samples."""
