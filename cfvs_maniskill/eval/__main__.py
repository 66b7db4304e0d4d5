"""`python -m cfvs_maniskill.eval`: many agents x tasks x objects x initial errors, resumable.

Every (task, agent, object, initial error, episode) is a job with a fixed seed; finished
episodes append to OUT/episodes.jsonl. Killed at any moment and started again with the
same arguments, it runs only the jobs that are missing. The same scene (seed) is used for
every agent, so agents are compared on identical episodes.
"""

from __future__ import annotations

import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import tyro

from cfvs_maniskill.cli import fail as _fail
from cfvs_maniskill.constants import DEFAULT_SEARCH_RADIUS

if TYPE_CHECKING:
    from cfvs_maniskill.robots.mounts import Mount
    from cfvs_maniskill.sensing.profile import SensorProfile


@dataclass
class EvalArgs:
    """Evaluate agents on peg-in-hole tasks; resumable JSON-lines results."""

    out: Path = Path("results/eval")
    """Output directory: episodes.jsonl (one line per finished episode) and summary.md."""
    tasks: tuple[str, ...] = ("PegInsert3DoF", "PegInsert4DoF", "PegInsert6DoF")
    """Task names (bundled or in the user folder) or paths to task files."""
    agents: tuple[str, ...] = ("cfvs",)
    """Agents (see `python -m cfvs_maniskill.run --help`), e.g. cfvs icp icp_kpts 3drhd kovis."""
    objects: tuple[str, ...] = ("test",)
    """Hole objects by name or split (train, test, all), per task those its peg fits."""
    init_errors: tuple[Literal["small", "large"], ...] = ("small", "large")
    episodes_per_object: int = 25
    """Episodes per (task, agent, object, initial error)."""
    seed: int = 0
    """Base seed; each episode's seed is a stable hash of (task, object, error, episode, seed)."""
    workers: int = 2
    """Worker processes (each reuses one env and one agent across episodes); a worker that
    dies is replaced and its job retried once, then recorded as crashed. 0: run in this
    process (no protection from a crash; for debugging)."""
    retry_crashed: bool = False
    """Run the jobs recorded as crashed again (their new records replace the old)."""
    rerun_stale: bool = False
    """Run again the jobs whose records are stale by `report --check`'s rule (episode code
    their agent runs, weights, sensor, task or hole files that are not today's): those
    records leave the folder first (git keeps them). Refused on a frozen set's results."""
    backend: Literal["local", "ray"] = "local"
    """local: worker processes on this machine; ray: one Ray actor per worker."""
    address: str | None = None
    """Ray cluster address (HOST:PORT) with --backend ray; none: start a local Ray."""
    assets: tuple[Path, ...] = ()
    """Extra hole-object folders or files."""
    search_radius: float = DEFAULT_SEARCH_RADIUS
    """Compliant search radius of the shared executor, metres (0: the paper's protocol)."""
    sensors: tuple[str, ...] = ("ideal",)
    """Sensor profiles, a grid dimension: names of files in sensors/ (ideal: the paper's
    protocol; realistic: a D405-class stereo camera, hand-eye error, a noisy wrist
    force/torque sensor) or paths to profile files."""


def find_tasks(tasks: tuple[str, ...]) -> dict:
    """Task name -> TaskConfig of each task given by name or file; an unknown task, a bad
    file or two tasks of one name -> exit 2 naming it."""
    from cfvs_maniskill.envs.lookup import find_task

    out: dict = {}
    for t in tasks:
        try:
            cfg = find_task(t)
        except ValueError as e:
            _fail(str(e))
        if out.setdefault(cfg.name, cfg).source != cfg.source:
            _fail(f"two tasks named '{cfg.name}': {out[cfg.name].source} and {cfg.source}")
    return out


def resolve(args: EvalArgs, tasks: dict | None = None) -> dict[str, list[str]]:
    """Task -> object names; unknown task / agent / object -> exit 2 with the valid names.
    `tasks`: find_tasks(args.tasks), when the caller has it already."""
    from cfvs_maniskill.objects.library import SelectionError, load_library
    from cfvs_maniskill.policies.registry import resolve_agent

    for a in args.agents:
        try:
            resolve_agent(a)
        except KeyError as e:
            _fail(e.args[0])
    if args.episodes_per_object < 1:
        _fail(f"--episodes-per-object must be >= 1, got {args.episodes_per_object}")
    lib = load_library([str(a) for a in args.assets])
    out: dict[str, list[str]] = {}
    hosted: dict[str, list[str]] = {}  # named object -> tasks that can use it
    for task in (tasks or find_tasks(args.tasks)).values():
        base, profile = task.name, task.peg
        names: dict[str, None] = {}
        for sel in args.objects:
            named = sel in lib.specs
            if named and profile not in lib.specs[sel].hole:
                # A named object may suit only some of the tasks: skip just this pair.
                holes = ", ".join(lib.specs[sel].hole)
                print(f"skipping {base} x {sel}: it cannot host a {profile} peg (holes: {holes})")
                hosted.setdefault(sel, [])
                continue
            try:
                names.update(dict.fromkeys(s.name for s in lib.select([sel], profile=profile)))
            except SelectionError as e:
                _fail(str(e))
            if named:
                hosted.setdefault(sel, []).append(base)
        if names:
            out[base] = sorted(names)
        else:
            print(f"skipping {base}: none of the objects {list(args.objects)} fits its peg")
    for name, tasks in hosted.items():
        if not tasks:
            _fail(
                f"object '{name}' fits none of the tasks {list(args.tasks)} "
                f"(it hosts {', '.join(lib.specs[name].hole)} pegs)"
            )
    return out


def unbuildable(
    agents: list[str],
    tasks: dict,
    weights: dict[tuple[str, str, str], dict] | None = None,
    mounts: tuple[Mount, ...] = (),
) -> set[tuple[str, str]]:
    """(task, agent) pairs whose agent cannot be built for the task (e.g. no trained
    weights for its peg): each skipped with one line saying why; an agent that can run
    none of the tasks -> exit 2. `tasks`: name -> TaskConfig. `weights`, when given, gets
    the weights files each (task, agent) loads with its camera on each of `mounts` (the
    sensors' mounts, robots/mounts.Mount; settings.Settings.weights)."""
    from cfvs_maniskill.nets.checkpoint import WeightsError
    from cfvs_maniskill.policies.interface import TaskSpec
    from cfvs_maniskill.policies.registry import PRIVILEGED, resolve_agent
    from cfvs_maniskill.provenance import track_weights
    from cfvs_maniskill.robots.mounts import DEFAULT_MOUNT, MOUNTS

    skip: set[tuple[str, str]] = set()
    for a in agents:
        if a in PRIVILEGED:
            continue  # built from the env itself: nothing to check beforehand
        reasons = []
        for t, cfg in tasks.items():
            try:
                with track_weights() as on_default:
                    resolve_agent(a)(TaskSpec.of(cfg))
            except WeightsError as e:
                print(f"skipping {t} x {a}: {e}")
                skip.add((t, a))
                reasons.append(str(e))
                continue
            except Exception:  # a bug in the agent: each of its episodes records it
                continue
            if weights is None:
                continue
            for mount in mounts:
                if mount == MOUNTS[DEFAULT_MOUNT]:  # built just now
                    weights[(t, a, mount.name)] = dict(sorted(on_default.items()))
                    continue
                try:
                    with track_weights() as on_mount:
                        resolve_agent(a)(TaskSpec.of(cfg, mount))
                except Exception:  # its episodes on that mount record why
                    continue
                weights[(t, a, mount.name)] = dict(sorted(on_mount.items()))
        if tasks and len(reasons) == len(tasks):
            _fail(f"agent '{a}' can run none of the tasks {list(tasks)}: {reasons[0]}")
    return skip


def sensor_files(sensors: tuple[str, ...]) -> dict[str, tuple[str, SensorProfile]]:
    """Profile name -> (name or file as given, the profile read, `source` its file); an
    unknown profile or a bad file -> exit 2 naming it."""
    from cfvs_maniskill.sensing.profile import load_profile

    out = {}
    for s in sensors:
        try:
            profile = load_profile(s)
        except ValueError as e:
            _fail(str(e))
        out[profile.name] = (s, profile)
    return out


MAX_JOBS = 100_000
"""The largest grid one evaluation takes (at ~20 s an episode, 23 CPU-days): a larger one is
a typo, refused before it is built."""


def grid_size(args: EvalArgs, objects: dict[str, list[str]], sensors: int) -> int:
    per_task = len(args.agents) * len(args.init_errors) * args.episodes_per_object * sensors
    return sum(len(o) for o in objects.values()) * per_task


def main(args: EvalArgs) -> int:
    from cfvs_maniskill.eval.jobs import make_jobs
    from cfvs_maniskill.eval.results import ResultsError, exclusive, frozen, read_done
    from cfvs_maniskill.eval.settings import Settings, differences
    from cfvs_maniskill.eval.worker import WorkerConfig
    from cfvs_maniskill.provenance import sha256

    configs = find_tasks(args.tasks)
    objects = resolve(args, configs)
    files = sensor_files(args.sensors)
    if (n := grid_size(args, objects, len(files))) > MAX_JOBS:
        _fail(f"the grid holds {n} jobs; one evaluation takes at most {MAX_JOBS}: narrow it")
    tasks = {n: c for n, c in configs.items() if n in objects}
    now = Settings(
        seed=args.seed,
        search_radius=args.search_radius,
        sensors={name: sha256(p.source) for name, (_, p) in files.items()},
        tasks={name: sha256(c.source) for name, c in tasks.items()},
    )
    mounts = {m.name: m for m in (p.camera_mount for _, p in files.values())}
    skip = unbuildable(list(args.agents), tasks, now.weights, tuple(mounts.values()))
    jobs = make_jobs(
        objects,
        list(args.agents),
        list(args.init_errors),
        args.episodes_per_object,
        args.seed,
        list(files),
    )
    jobs = [j for j in jobs if (j.task, j.agent) not in skip]
    if args.rerun_stale and (held := frozen(args.out)):
        _fail(f"--rerun-stale: {args.out} holds a frozen set's records ({held}), run once")
    try:
        args.out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        _fail(f"--out {args.out}: cannot be a results folder ({e.strerror or e})")
    path = args.out / "episodes.jsonl"
    cfg = WorkerConfig(
        objects=objects,
        assets=[str(a) for a in args.assets],
        search_radius=args.search_radius,
        sensor_files={name: given for name, (given, _) in files.items()},
        task_files={n: c.source for n, c in tasks.items()},
    )
    try:
        with exclusive(path):
            done = read_done(path)
            if args.rerun_stale:
                done = drop_stale(path, done, {j.key for j in jobs})
            if diff := differences(done, now):
                _fail(
                    f"{path} holds records made with other settings; resume with the settings "
                    "that made them, or use another --out:\n  " + "\n  ".join(diff)
                )
            return _evaluate(args, jobs, path, done, cfg, now)
    except ResultsError as e:
        _fail(str(e))


def drop_stale(path: Path, done: dict[str, dict], wanted: set[str]) -> dict[str, dict]:
    """`done` without its stale records (report/trace.py) of the jobs `wanted` (the
    command's: the records of agents or tasks it does not run stay), which leave the
    results files; one line per reason says how many went."""
    from collections import Counter

    from cfvs_maniskill.eval.results import drop
    from cfvs_maniskill.report import trace

    reasons: Counter = Counter()
    stale = set()
    for key, rec in done.items():
        if key not in wanted or rec.get("crashed"):
            continue
        if why := trace.stale_reasons(rec, trace.resolve(rec)):
            stale.add(key)
            reasons.update(why)
    drop(path, stale)
    for why, n in reasons.most_common():
        print(f"stale: {why} ({n} records)")
    print(f"{len(stale)} stale records removed from {path.parent}; their jobs run again")
    return {k: r for k, r in done.items() if k not in stale}


def _evaluate(args: EvalArgs, jobs, path: Path, done: dict, cfg, now) -> int:
    """Run the jobs not in `done` (the caller holds the folder's lock), then summary.md."""
    from tqdm import tqdm

    from cfvs_maniskill.errors import FileFieldError
    from cfvs_maniskill.eval.crash import JobError
    from cfvs_maniskill.eval.local import BACKENDS
    from cfvs_maniskill.eval.results import ResultsError, append, fold_into_compressed
    from cfvs_maniskill.eval.summary import write_summary

    if args.retry_crashed:
        done = {k: r for k, r in done.items() if not r.get("crashed")}
    todo = [j for j in jobs if j.key not in done]
    print(f"{len(jobs)} jobs, {len(jobs) - len(todo)} already in {path}, {len(todo)} to run")
    t0 = time.perf_counter()
    t_first = None
    started = max(1, min(args.workers, len(todo)))
    ok = crashed = 0
    bar = tqdm(total=len(todo), unit="ep", desc="eval", file=sys.stderr, smoothing=0.05)
    try:
        for rec in BACKENDS[args.backend](todo, args.workers, cfg, address=args.address):
            append(path, rec)
            if bar.n + 1 == started:  # by then (about) every worker has built its scene
                t_first = time.perf_counter()
            ok += rec["success"]
            crashed += bool(rec.get("crashed"))
            bar.update(1)
            bar.set_postfix(success=f"{ok}/{bar.n}", **({"crashed": crashed} if crashed else {}))
    except KeyboardInterrupt:
        bar.close()
        print(f"interrupted: {bar.n} episodes saved in {path}; run again to finish")
        return 130
    except (ResultsError, FileFieldError, JobError) as e:
        # A hole object only a worker builds (its mesh) can turn out unusable mid-run:
        # name it; the episodes already appended stay, and a rerun resumes after them.
        bar.close()
        print(f"error: {e}; {bar.n} episodes saved in {path}", file=sys.stderr)
        return 1
    bar.close()
    wall = time.perf_counter() - t0
    line = f"{len(todo)} episodes in {wall:.0f} s ({len(todo) / max(wall, 1e-9):.2f} episodes/s"
    if t_first and len(todo) > started:
        # Without the workers' start-up (scene build, shader compile): the steady rate,
        # counted once as many episodes as workers are in (one worker's start-up can end
        # seconds after another's: counting from the first would charge it to the rate).
        steady = (len(todo) - started) / max(time.perf_counter() - t_first, 1e-9)
        line += f"; {steady:.2f} episodes/s once every worker had started"
    print(line + ")")
    fold_into_compressed(path)
    summary = write_summary(path, args.out / "summary.md", asdict(args), now)
    print(summary)
    return 0


if __name__ == "__main__":
    sys.exit(main(tyro.cli(EvalArgs)))
