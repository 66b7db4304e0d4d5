"""Run an agent on a peg-in-hole task: `python -m cfvs_maniskill.run --task PegInsert6DoF`.

Prints one line per episode and a summary (success rate with its 95% Wilson interval, mean
simulated servo time); `--out` appends one JSON object per episode; `--video` writes an mp4
per episode, rendered off-screen (no display, no GPU needed).
"""

from __future__ import annotations

import functools
import sys
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import tyro

from cfvs_maniskill.cli import fail as _fail
from cfvs_maniskill.constants import DEFAULT_SEARCH_RADIUS


@dataclass
class RunArgs:
    """Run an agent on a peg-in-hole task and report its success rate."""

    task: str = "PegInsert6DoF"
    """Task name or env id (bundled, or a file in the user folder's tasks/), e.g.
    PegInsert3DoF or PegInsert6DoF-v1, or a path to a task file (my_task.yaml)."""
    agent: str = "cfvs"
    """Policy: cfvs (shipped weights), cfvs_no_c2f / cfvs_no_map / cfvs_aug / cfvs_no_rim
    (the paper's ablations; every CFVS switch has one, see docs/cfvs.md), icp / icp_kpts /
    3drhd / kovis (its baselines), oracle (reads the true hole pose), cfvs@DIR (your
    weights), package.module:Class (your agent)."""
    episodes: int = 10
    """Number of episodes."""
    seed: int = 0
    """Seed of the first episode; episode i uses seed + i."""
    objects: tuple[str, ...] = ()
    """Hole objects by name or split (train, test, all). Default: the task file's list."""
    assets: tuple[Path, ...] = ()
    """Extra directories (or files) of hole-object YAML specs, beside assets/holes/."""
    init_error: Literal["small", "large"] = "small"
    """Initial peg-to-hole distance: small (15 cm) or large (30 cm)."""
    out: Path | None = None
    """Append one JSON line per episode to this file. Each record is keyed by (task, agent,
    initial error, seed, sensor, search radius, objects): run again, an episode already there
    is skipped, so no report counts it twice; one run at a time per file (a lock)."""
    video: Path | None = None
    """Write one mp4 per episode into this directory: a lit close view of the hole, an
    overview and the wrist camera with the agent's estimated hole frame, captioned with the
    phase, the contact force and the outcome (about 10 s of rendering per episode on a
    2-core CPU; docs/videos.md)."""
    search_radius: float = DEFAULT_SEARCH_RADIUS
    """Compliant spiral search when the peg stalls on the rim, up to this radius, metres
    (beyond the paper, as real assembly cells do; applies to every agent). 0: the paper's
    plain insertion."""
    sensor: str = "ideal"
    """Sensor profile: a file in sensors/ (ideal: the paper's protocol; realistic: a
    D405-class stereo camera, 1.5 mm / 0.5 deg hand-eye error, a noisy wrist force/torque
    sensor) or a path to a profile file."""


def resolve_task(spec: str):
    """Task name, env id or task file -> its TaskConfig, or exit 2 naming what is wrong."""
    from cfvs_maniskill.envs.lookup import find_task

    try:
        return find_task(spec)
    except ValueError as e:
        _fail(str(e))


def main(args: RunArgs) -> list:
    from cfvs_maniskill.eval.results import ResultsError, exclusive, read_done
    from cfvs_maniskill.objects.library import SelectionError
    from cfvs_maniskill.policies.registry import resolve_agent
    from cfvs_maniskill.session import make_env, open_session

    task = resolve_task(args.task)
    try:
        resolve_agent(args.agent)
    except KeyError as e:
        _fail(e.args[0])
    if args.episodes < 1:
        _fail(f"--episodes must be >= 1, got {args.episodes}")
    from cfvs_maniskill.sensing.profile import load_profile

    try:
        load_profile(args.sensor)
    except ValueError as e:
        _fail(str(e))
    try:
        env = make_env(
            task,
            args.agent,
            objects=args.objects or None,
            assets=args.assets,
            sensor=args.sensor,
            init_error=args.init_error,
        )
    except SelectionError as e:
        _fail(str(e))
    except FileNotFoundError as e:
        _fail(str(e))
    label = task.env_id  # a task file's own name, not the generic id
    film = None
    if args.video:
        from cfvs_maniskill.rendering.film import Film

        film = Film(env, args.agent)
    from cfvs_maniskill.nets.checkpoint import WeightsError

    try:
        session = open_session(env, args.agent, args.search_radius)
    except WeightsError as e:
        _fail(str(e))
    seeds = [args.seed + i for i in range(args.episodes)]
    done: dict = {}
    with ExitStack() as held:
        if args.out:
            try:
                args.out.parent.mkdir(parents=True, exist_ok=True)
                held.enter_context(exclusive(args.out))
                done = read_done(args.out)
            except (OSError, ResultsError) as e:
                _fail(f"--out {args.out}: {e}")
        key = functools.partial(run_key, label, args)
        if skipped := [s for s in seeds if key(s) in done]:
            print(f"{len(skipped)} of the {len(seeds)} episodes are in {args.out} already: skipped")
            seeds = [s for s in seeds if key(s) not in done]
        results = _episodes(args, session, film, label, seeds, key)
    env.close()
    if not results:
        return results
    _print_summary(args, label, results)
    return results


def run_key(label: str, args: RunArgs, seed: int) -> str:
    """A run record's key: everything that decides the episode besides the code and files."""
    objects = ",".join(args.objects) or "task"  # the selection the seed draws the object from
    return (
        f"run|{label}|{args.agent}|{args.init_error}|{seed}|{args.sensor}|{args.search_radius}"
        f"|{objects}"
    )


def _episodes(args: RunArgs, session, film, label: str, seeds: list[int], key) -> list:
    from tqdm import tqdm

    from cfvs_maniskill.eval.results import ResultsError, append

    results = []
    bar = tqdm(seeds, desc=f"{args.agent} on {label}", unit="ep", file=sys.stderr)
    for i, seed in enumerate(bar):
        r = session.episode(seed, film=film)
        results.append(r)
        if film is not None:
            name = f"{label.removesuffix('-v1')}_{args.agent}_seed{r.seed}.mp4"
            path = film.write(args.video / name.replace(":", "_").replace("/", "_"))
            tqdm.write(f"  video {path} ({len(film.frames)} frames, {film.render_s:.0f} s)")
        line = (
            f"episode {i:4d} seed {r.seed:6d} {r.object:20s} "
            f"{'success' if r.success else 'FAIL   '} servo {r.servo_time_s:5.2f} s"
            + (f"  ({r.reason})" if r.reason else "")
        )
        tqdm.write(line)
        if args.out:
            try:  # the eval runner's all-or-nothing append
                append(args.out, {**r.to_json(), "key": key(seed), "init_error": args.init_error})
            except ResultsError as e:
                _fail(str(e))
        bar.set_postfix(success=f"{sum(x.success for x in results)}/{len(results)}")
    return results


def _print_summary(args: RunArgs, label: str, results: list) -> None:
    from cfvs_maniskill.stats import wilson_interval

    k, n = sum(r.success for r in results), len(results)
    lo, hi = wilson_interval(k, n)
    servo = sum(r.servo_time_s for r in results) / n
    print(
        f"{args.agent} on {label} ({args.init_error} initial error, {args.sensor} sensor): success {k}/{n} = "
        f"{k / n:.2f} (95% CI {lo:.2f}-{hi:.2f}), mean servo time {servo:.2f} s"
    )
    if args.video:
        print(f"videos in {args.video}")


if __name__ == "__main__":
    main(tyro.cli(RunArgs))
