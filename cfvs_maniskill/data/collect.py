"""Collect the coarse (OAKN) and fine (OPN) datasets in the simulator (paper: Data generation).

Sample i is drawn from its own generator seeded by (seed, i) -- the scene, the object, the
start and the perturbation -- so a resumed collection continues exactly where it stopped.

* coarse: the peg at the task's initial configuration, 15-30 cm (the task's init_error
  range) from a randomly placed hole object; the cloud, keypoints, offsets, confidence.
* fine: the peg at the true pre-insertion pose moved by a random tool-frame offset
  (-dt, -dtheta, ranges from the task file); the cropped cloud and the action (dt, dtheta)
  that undoes it. The robot is set to the perturbed pose directly (no motion is needed to
  render what the camera would see there).
* kovis (the KOVIS baseline): rollouts as KOVIS's own data generator makes them: from the
  pre-insertion pose, 5 steps along a random direction (within the task's degrees of
  freedom) of one random length; at each pose the wrist camera's stereo pair of grey
  images, their depth and segmentation (the decoder's targets), and the tool-frame motion
  (dt, dtheta) back to the pre-insertion pose.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from scipy.spatial.transform import Rotation
from tqdm import tqdm

from cfvs_maniskill import geometry as G
from cfvs_maniskill.constants import PRE_INSERT_HEIGHT
from cfvs_maniskill.data import store
from cfvs_maniskill.data.procedural import check_family, procedural_specs
from cfvs_maniskill.nets.kovis import KOVISConfig
from cfvs_maniskill.perception import labels as L
from cfvs_maniskill.perception.clouds import (
    MIN_OBJECT_POINTS,
    fine_crop,
    object_points,
    sample_fixed,
    world_to_tool,
)

GROUP_SIZE = 12
"""Procedural bodies per simulator scene; the scene is rebuilt for the next group."""
BLOCK = 240
"""Consecutive samples drawn from one group of objects."""
CHUNK = 40
"""Samples per crash-safe chunk file."""
ROLLOUT_FRAMES = 5
"""KOVIS: frames per rollout (its rollout_step)."""
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


@dataclass
class CollectArgs:
    """Collect a CFVS dataset (HDF5). Resumes if FILE or its FILE.parts/ exist."""

    task: str = "PegInsert6DoF"
    """Task name (bundled or in the user folder) or a path to a task file."""
    kind: str = "coarse"
    """coarse (OAKN: keypoints + confidence), fine (OPN: actions) or kovis (images +
    motion to the goal, for the KOVIS baseline)."""
    samples: int = 2000
    """Total number of samples the file should hold."""
    out: Path = Path("data/coarse.h5")
    """Output HDF5 file."""
    objects: tuple[str, ...] = ("train",)
    """Hole objects (names or splits). Training data never uses the test split by default."""
    procedural: bool = False
    """Also use procedurally varied training bodies (boxes, cylinders, prisms)."""
    procedural_count: int = 240
    """How many procedural bodies (with --procedural)."""
    procedural_features: bool = False
    """With --procedural: mesh bodies with a raised block (wall, step, boss) and / or a notch
    (edge, inner corner) beside a hole placed anywhere its walls allow."""
    procedural_parts: bool = False
    """With --procedural: tall bodies (10-26 cm) cut like machined parts, inclined planar
    faces falling away from the hole, a curved boss beside it (not with the features)."""
    procedural_family: str = "plain"
    """With --procedural: the body family, one of plain, features, parts, ribs, pockets,
    narrow (data/procedural.py, data/shapes.py; composite and grooved are held out of
    training); --procedural-features and --procedural-parts are the same as features and
    parts."""
    points: int = 1024
    """Points per sample after sampling (fixed N)."""
    seed: int = 0
    """Base seed: sample i is drawn from (seed, i)."""
    assets: tuple[str, ...] = ()
    """Extra hole-object folders or files."""
    sensor: str = "ideal"
    """Sensor profile the observations are taken with (sensors/<name>.yaml or a path): train
    on the noise the agent will meet."""
    rollout_step: tuple[float, float] = ROLLOUT_STEP
    """kovis: range of a rollout's step, m (log-uniform); e.g. 0.02 0.08 for far views only."""


def file_attrs(args: CollectArgs, task) -> dict:
    drawn = family(args) if args.procedural else "plain"
    attrs = {
        "format": store.FORMAT,
        "kind": args.kind,
        "task": args.task,
        "peg": task.peg,
        "num_points": args.points,
        "seed": args.seed,
        "objects": json.dumps(list(args.objects)),
        "procedural": args.procedural_count if args.procedural else 0,
        "procedural_features": drawn == "features",
        "frame": "tool",
        "units": "metres, radians",
        "keypoint_spacing": L.KEYPOINT_SPACING,
        "confidence_sigma": L.CONFIDENCE_SIGMA,
        "config": json.dumps({k: str(v) for k, v in dataclasses.asdict(args).items()}),
        "task_config": json.dumps(dataclasses.asdict(task)),
    }
    # Only when set, so older files still resume; one family however the flags named it.
    if drawn == "parts":
        attrs["procedural_parts"] = True
    if drawn not in ("plain", "features", "parts"):
        attrs["procedural_family"] = drawn
    if args.kind == "kovis" and tuple(args.rollout_step) != ROLLOUT_STEP:
        # Only when not the default, so files collected before the option still resume.
        attrs["rollout_step"] = json.dumps(list(args.rollout_step))
    return attrs


def family(args: CollectArgs) -> str:
    """The procedural body family the flags name (DatasetError when they disagree)."""
    named = [
        f
        for f, on in (("features", args.procedural_features), ("parts", args.procedural_parts))
        if on
    ]
    if args.procedural_family != "plain":
        named.append(args.procedural_family)
    if len(set(named)) > 1:
        raise store.DatasetError(
            "--procedural-features / --procedural-parts / --procedural-family: expected one "
            f"body family, got {named}"
        )
    chosen = named[0] if named else "plain"
    try:
        check_family(chosen)
    except ValueError as e:
        raise store.DatasetError(f"--procedural-family: {e}") from None
    return chosen


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


class Collector:
    """Owns the simulator scene(s) and draws sample i on demand."""

    def __init__(self, args: CollectArgs, task):
        from cfvs_maniskill.objects.library import load_library

        self.args, self.task = args, task
        self.assets = list(args.assets)
        lib = load_library(self.assets)
        base = [s.name for s in lib.select(list(args.objects), profile=task.peg)]
        self.groups: list[list[str]] = [base]
        if args.procedural:
            folder, names = procedural_specs(
                args.procedural_count,
                args.seed,
                task.peg,
                task.clearance,
                task.hole_depth,
                family(args),
            )
            self.assets.append(str(folder))
            groups = [names[i : i + GROUP_SIZE] for i in range(0, len(names), GROUP_SIZE)]
            # Every scene also holds the named objects, so they stay in the mix.
            self.groups = [base + g for g in groups]
        self.env = None
        self.group = -1

    def _env_for(self, group: int):
        import gymnasium as gym

        from cfvs_maniskill.envs.lookup import make_args

        if group != self.group:
            if self.env is not None:
                self.env.close()
            # KOVIS: the stereo imagers, and segmentation for the decoder's targets.
            kovis = dict(obs_mode="rgb+depth+segmentation", stereo=True)
            env_id, task_kwargs = make_args(self.task)
            self.env = gym.make(
                env_id,
                **task_kwargs,
                **(kovis if self.args.kind == "kovis" else dict(obs_mode="pointcloud")),
                objects=tuple(self.groups[group]),
                assets=tuple(self.assets),
                sensor=self.args.sensor,
            )
            self.group = group
        return self.env

    def sample(self, i: int, draw: int = 0) -> dict[str, np.ndarray] | None:
        """Sample i (its `draw`-th attempt), or None if that draw gave no usable view."""
        args, task = self.args, self.task
        rng = np.random.default_rng([args.seed, i, draw])
        group = (i // BLOCK) % len(self.groups)
        env = self._env_for(group)
        u = env.unwrapped
        names = self.groups[group]
        obj = names[int(rng.integers(len(names)))]
        lo, hi = min(task.init_error.values()), max(task.init_error.values())
        u.init_error_m = float(rng.uniform(lo, hi))
        # The fine kind looks only after moving the peg: skip rendering the start view.
        u.defer_obs = args.kind in ("fine", "kovis")
        try:
            obs, _ = env.reset(seed=int(rng.integers(2**31 - 1)), options={"object": obj})
        finally:
            u.defer_obs = False
        H = u.hole_pose.copy()
        if args.kind == "coarse":
            return self._coarse(u, obs, H, rng, i)
        if args.kind == "kovis":
            return self._kovis(u, H, rng, i)
        return self._fine(u, H, rng, i)

    def _common(self, u, points, tcp, H, i):
        return {
            "points": points.astype(np.float32),
            "tcp_pose": tcp,
            "hole_pose": H,
            "object": np.array(u.episode_info["object"]),
            "sample_index": np.array(i, dtype=np.int64),
        }

    def _coarse(self, u, obs, H, rng, i):
        tcp = u.tcp_matrix()
        pts = object_points(obs["pointcloud"]["xyzw"][0].numpy(), tcp, self.task.peg)
        if len(pts) < MIN_OBJECT_POINTS:
            return None  # the camera hardly sees the object: redraw
        pts = sample_fixed(pts, self.args.points, rng)
        k = world_to_tool(L.keypoints_world(H, tcp, self.task.peg), tcp)
        row = self._common(u, pts, tcp, H, i)
        row.update(
            keypoints=k.astype(np.float32),
            offsets=L.offsets(pts, k),
            confidence=L.confidence(pts, k[0]),
            init_error=np.array(np.linalg.norm(tcp[:3, 3] - H[:3, 3]), dtype=np.float32),
        )
        return row

    def _fine(self, u, H, rng, i):
        task = self.task
        q = fine_start(u, H, rng, task.fine_max_translation)
        if q is None:
            return None
        u.agent.reset(torch.as_tensor(q, dtype=torch.float32)[None])
        obs = u.get_obs()
        tcp = u.tcp_matrix()  # what the robot really reached (IK is exact to < 1 mm)
        target = u.insertion_pose(-PRE_INSERT_HEIGHT, H, tcp)
        pts = fine_crop(object_points(obs["pointcloud"]["xyzw"][0].numpy(), tcp, task.peg))
        if len(pts) < MIN_OBJECT_POINTS:
            return None  # the crop sees (almost) nothing: not a useful sample
        pts = sample_fixed(pts, self.args.points, rng)
        row = self._common(u, pts, tcp, H, i)
        row.update(action=L.fine_action(tcp, target), target_pose=target)
        return row

    def _kovis(self, u, H, rng, i):
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

        task = self.task
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
            step = float(np.exp(rng.uniform(*np.log(self.args.rollout_step))))
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

    def close(self):
        if self.env is not None:
            self.env.close()


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


def collect(args: CollectArgs) -> int:
    """Collect until `args.out` holds `args.samples` samples; return the count."""
    from cfvs_maniskill.envs.lookup import find_task

    if args.kind not in ("coarse", "fine", "kovis"):
        raise store.DatasetError(f"--kind: expected coarse, fine or kovis, got {args.kind!r}")
    task = find_task(args.task)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    family(args)  # one body family, a training one
    if args.kind == "kovis" and not 0 < args.rollout_step[0] <= args.rollout_step[1] <= 0.1:
        raise store.DatasetError(
            f"--rollout-step: expected 0 < MIN <= MAX <= 0.1 m, got {args.rollout_step}"
        )
    attrs = file_attrs(args, task)
    have = store.existing_count(out, attrs)
    if have >= args.samples:
        if store.parts_dir(out).exists():
            have = store.finalize(out, attrs)
        return have
    store.start_parts(out, attrs)
    collector = Collector(args, task)
    rows: list[dict] = []
    first = have
    t0 = time.perf_counter()
    bar = tqdm(total=args.samples, initial=have, unit="sample", desc=f"{args.kind} {args.task}")
    try:
        i = have
        while i < args.samples:
            row = _draw(collector, i)
            rows.append(row)
            i += 1
            bar.update(1)
            if len(rows) == CHUNK or i == args.samples:
                store.write_part(out, first, {k: np.stack([r[k] for r in rows]) for k in rows[0]})
                first, rows = i, []
    finally:
        bar.close()
        collector.close()
    n = store.finalize(out, attrs)
    rate = (n - have) / max(time.perf_counter() - t0, 1e-9)
    print(f"{out}: {n} samples ({rate:.1f} samples/s this run)")
    return n


def _draw(collector: Collector, i: int) -> dict:
    """Sample i: the first usable of its deterministic draws 0, 1, 2, ..."""
    for draw in range(100):
        row = collector.sample(i, draw)
        if row is not None:
            return row
    raise RuntimeError(f"sample {i}: no usable view in 100 draws")
