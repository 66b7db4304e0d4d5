"""How far the peg's section sinks into the hole's walls while it is inserted, per clearance:
`python -m benchmarks.penetration` (also part of `python -m benchmarks.run`).

Measured from the bodies' poses (scene.wall_penetration, the success test's own measure),
not from PhysX's contact list: without its persistent contact manifold PhysX reuses cached
contacts while a pair barely moves, and those report separations of 0 or more where the
poses overlap (a section 0.27 mm into the wall read 0.006 mm clear; a ray cast against the
peg's collision shape confirmed the pose). Each control step of an insertion with the full
section below the opening counts once; the end is the pose that is scored."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import tyro

from benchmarks.common import Figure

TASKS = ("PegInsert6DoF", "PegInsert6DoF-1mm", "PegInsert6DoF-0.5mm")


@dataclass
class Args:
    """Measure the peg's penetration of the hole's walls during and at the end of CFVS
    insertions under the D405 model (its hand-eye error makes the wrist push the walls)."""

    episodes: int = 40
    """Episodes per task (test objects, 15 cm; seeds 7000 on)."""
    sensor: str = "realistic"
    """Sensor profile: `realistic` leaves the most lateral error for the insertion."""
    compare_iterations: int = 60
    """Also run the tight tasks with this many PhysX position iterations instead of the
    env's (ManiSkill's 15), for the penetration and the cost (0: skip)."""


def _penetrations(task: str, args: Args, iterations: int | None) -> dict:
    """Per-step and end penetration (m), successes and wall time of `args.episodes` CFVS
    episodes on `task`, with PhysX position iterations `iterations` (None: the env's)."""
    from cfvs_maniskill.envs.scene import wall_penetration
    from cfvs_maniskill.geometry import inv
    from cfvs_maniskill.session import make_env, open_session

    kw = {}
    if iterations is not None:
        kw["sim_config"] = dict(scene_config=dict(solver_position_iterations=iterations))
    env = make_env(task, "cfvs", sensor=args.sensor, **kw)
    u = env.unwrapped
    session = open_session(env, "cfvs")
    steps: list[float] = []
    ends: list[float] = []
    ok, wall = 0, 0.0

    def pen() -> float:
        return wall_penetration(u.task, inv(u.hole_pose) @ u.tcp_matrix())

    class Probe:  # a film that only measures: run_episode calls it every control step
        def start(self) -> None: ...
        def note(self, *a) -> None: ...
        def finish(self, *a) -> None: ...
        def on_step(self, executor) -> None:
            p = pen()
            if np.isfinite(p):
                steps.append(p)

    for i in range(args.episodes):
        t = time.perf_counter()
        r = session.episode(7000 + i, film=Probe())
        wall += time.perf_counter() - t
        ok += r.success
        if r.wall_penetration_m is not None:  # the record's own end measure (scene.score)
            ends.append(r.wall_penetration_m)
    iters = u.sim_config.scene_config.solver_position_iterations
    env.close()
    return dict(steps=np.array(steps), ends=np.array(ends), ok=ok, wall=wall, iters=iters)


def _row(task: str, room: float, m: dict, episodes: int) -> str:
    s, e = 1000 * m["steps"], 1000 * m["ends"]
    q = np.percentile(s, [50, 90, 99]) if len(s) else [np.nan] * 3
    return (
        f"| {task} | {1000 * room:.2f} | {m['iters']} | {len(s)} | {q[0]:.3f} | {q[1]:.3f} "
        f"| {q[2]:.3f} | {s.max() if len(s) else np.nan:.3f} | "
        f"{e.max() if len(e) else np.nan:.3f} | {m['ok']}/{episodes} | "
        f"{m['wall'] / episodes:.2f} s |"
    )


def measure(args: Args | None = None) -> tuple[list[Figure], str]:
    import torch

    args = args or Args()

    from cfvs_maniskill import TASKS as ALL
    from cfvs_maniskill.constants import hole_half_extent, peg_half_extent

    torch.set_num_threads(1)
    lines = [
        "| task | room per side, mm | solver iterations | steps | p50 mm | p90 | p99 | max | "
        "end max | success | wall / episode |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    figures = []
    for task in TASKS:
        cfg = ALL[task]
        room = hole_half_extent(cfg.peg, cfg.clearance) - peg_half_extent(cfg.peg)
        m = _penetrations(task, args, None)
        lines.append(_row(task, room, m, args.episodes))
        p99 = float(np.percentile(m["steps"], 99)) if len(m["steps"]) else float("nan")
        figures.append(
            Figure(
                f"wall penetration p99 during insertion, {task} ({args.sensor})",
                f"{1000 * p99:.3f} mm",
                f"< {1000 * room / 3:.3f} mm (a third of the room)",
                bool(p99 < room / 3),
                f"end max {1000 * m['ends'].max():.3f} mm, {m['ok']}/{args.episodes} success",
            )
        )
        if args.compare_iterations and m["iters"] != args.compare_iterations:
            base = _penetrations(task, args, args.compare_iterations)
            lines.append(_row(task, room, base, args.episodes))
            figures.append(
                Figure(
                    f"episode wall time, {task}: {m['iters']} / {base['iters']} solver iterations",
                    f"{m['wall'] / base['wall']:.2f}",
                    "report",
                    None,
                    f"{m['wall'] / args.episodes:.2f} vs {base['wall'] / args.episodes:.2f} s",
                )
            )
    detail = (
        f"CFVS, {args.sensor}, test objects, 15 cm, seeds 7000-{6999 + args.episodes}, per "
        "task; penetration of the peg's full section past the hole's wall at each control "
        "step with the section below the opening (negative: play left), and at the end:\n\n"
        + "\n".join(lines)
    )
    return figures, detail


def main(args: Args) -> int:
    from benchmarks.common import commit, machine

    figures, detail = measure(args)
    out = [
        "# Wall penetration",
        "",
        f"`python -m benchmarks.penetration`: {time.strftime('%Y-%m-%d %H:%M')}, commit "
        f"{commit()}. Machine: {machine()}.",
        "",
        "| figure | measured | target | | note |",
        "|---|---|---|---|---|",
        *[f.row() for f in figures],
        "",
        detail,
    ]
    path = Path(__file__).parent / "PENETRATION.md"
    path.write_text("\n".join(out) + "\n")
    print("\n".join(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(tyro.cli(Args)))
