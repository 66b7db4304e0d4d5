"""Collect a policy's dataset in the simulator: the kinds of sample the policies declare
(`policies/<name>/collect.py`: CFVS's coarse and fine, KOVIS's rollouts), chunked into a
resumable HDF5 file.

Sample i is drawn from its own generator seeded by (seed, i) -- the scene, the object, the
start and the perturbation -- so a resumed collection continues exactly where it stopped.
"""

from __future__ import annotations

import dataclasses
import importlib
import importlib.util
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from cfvs_maniskill.data import store
from cfvs_maniskill.data.procedural import check_family, procedural_specs
from cfvs_maniskill.perception import labels as L
from cfvs_maniskill.policies.dataset import SampleKind
from cfvs_maniskill.policies.kovis.collect import ROLLOUT_STEP
from cfvs_maniskill.policies.registry import POLICIES

GROUP_SIZE = 12
"""Procedural bodies per simulator scene; the scene is rebuilt for the next group."""
BLOCK = 240
"""Consecutive samples drawn from one group of objects."""
CHUNK = 40
"""Samples per crash-safe chunk file."""


@dataclass
class CollectArgs:
    """Collect a CFVS dataset (HDF5). Resumes if FILE or its FILE.parts/ exist."""

    task: str = "PegInsert6DoF"
    """Task name (bundled or in the user folder) or a path to a task file."""
    kind: str = "coarse"
    """A kind of sample a policy declares (`sample_kinds()`): coarse (CFVS's OAKN: keypoints
    + confidence), fine (CFVS's OPN: actions) or kovis (images + motion to the goal)."""
    samples: int = 2000
    """Total number of samples the file should hold."""
    chunk: int = CHUNK
    """Samples per crash-safe chunk file: a killed collection loses at most this many."""
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
    narrow, stands, decoys (data/procedural.py, data/shapes.py; the frozen sets' families
    are held out of training); --procedural-features and --procedural-parts are the same
    as features and parts."""
    points: int = 1024
    """Points per sample after sampling (fixed N)."""
    seed: int = 0
    """Base seed: sample i is drawn from (seed, i)."""
    assets: tuple[str, ...] = ()
    """Extra hole-object folders or files."""
    sensor: str = "ideal"
    """Sensor profile the observations are taken with (sensors/<name>.yaml or a path): train
    on the noise the agent will meet."""
    mount: str | None = None
    """A named camera mount (robots/mounts.py) in place of the profile's: views of another
    mount (e.g. flange_side) to train on beside the profile's own."""
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
    if args.mount is not None:
        attrs["mount"] = args.mount
    attrs.update(sample_kinds()[args.kind].attrs(args))
    return attrs


def sample_kinds() -> dict[str, SampleKind]:
    """Every policy folder's sample kinds (its collect.py's KINDS), by name."""
    out = {}
    for folder in POLICIES:
        module = f"cfvs_maniskill.policies.{folder}.collect"
        if importlib.util.find_spec(module) is not None:
            out.update(importlib.import_module(module).KINDS)
    return out


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


class Collector:
    """Owns the simulator scene(s) and draws sample i on demand."""

    def __init__(self, args: CollectArgs, task):
        from cfvs_maniskill.objects.library import load_library

        self.args, self.task = args, task
        self.kind = sample_kinds()[args.kind]
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

    def env_kwargs(self) -> dict:
        """What the kind needs of the camera, on `--mount` when given."""
        mount = {} if self.args.mount is None else {"camera_mount": self.args.mount}
        return {**self.kind.env_kwargs, **mount}

    def _env_for(self, group: int):
        import gymnasium as gym

        from cfvs_maniskill.envs.lookup import make_args

        if group != self.group:
            if self.env is not None:
                self.env.close()
            env_id, task_kwargs = make_args(self.task)
            self.env = gym.make(
                env_id,
                **task_kwargs,
                **self.env_kwargs(),
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
        u.defer_obs = self.kind.moves_first  # no start view rendered that nobody looks at
        try:
            obs, _ = env.reset(seed=int(rng.integers(2**31 - 1)), options={"object": obj})
        except RuntimeError as e:
            if not str(e).startswith("no reachable scene"):
                raise
            # e.g. a tall post where the start pose would be: the next draw, another body
            print(f"sample {i} draw {draw}: {e}; drawing again", file=sys.stderr)
            return None
        finally:
            u.defer_obs = False
        return self.kind.draw(args, task, u, obs, u.hole_pose.copy(), rng, i)

    def close(self):
        if self.env is not None:
            self.env.close()


def collect(args: CollectArgs) -> int:
    """Collect until `args.out` holds `args.samples` samples; return the count."""
    from cfvs_maniskill.envs.lookup import find_task

    kinds = sample_kinds()
    if args.kind not in kinds:
        raise store.DatasetError(f"--kind: expected one of {', '.join(kinds)}, got {args.kind!r}")
    task = find_task(args.task)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    family(args)  # one body family, a training one
    try:
        kinds[args.kind].check(args)
    except ValueError as e:
        raise store.DatasetError(str(e)) from None
    if args.chunk < 1:
        raise store.DatasetError(
            f"--chunk: expected a positive number of samples, got {args.chunk}"
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
            if len(rows) == args.chunk or i == args.samples:
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
