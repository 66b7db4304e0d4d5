"""CFVS speed on this CPU: network forward passes and a 6-DoF episode's wall time split
into render / physics / network / other. Part of `python -m benchmarks.run`; alone,
`python -m benchmarks.cfvs_speed` prints its figures (RESULTS.md is written by run.py)."""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass

import numpy as np
import torch
import tyro

from benchmarks.common import Figure, Timer


@dataclass
class Args:
    """Time OAKN / OPN forward passes and full CFVS 6-DoF episodes."""

    episodes: int = 30
    """CFVS 6-DoF episodes to time."""
    repeats: int = 50
    """Forward passes per network (median reported)."""
    threads: int = 1
    """torch threads (an eval worker uses 1)."""


def forward_ms(model, n_points: int, repeats: int) -> float:
    x = torch.rand(1, n_points, 3) * 0.2
    with torch.no_grad():
        for _ in range(3):
            model(x)
        times = []
        for _ in range(repeats):
            t = time.perf_counter()
            model(x)
            times.append(time.perf_counter() - t)
    return 1000 * statistics.median(times)


def measure(args: Args) -> tuple[list[Figure], str]:
    """OAKN / OPN forward times, and CFVS 6-DoF episodes' wall time against the render +
    physics time inside those same episodes (the floor any agent pays)."""
    import gymnasium as gym

    import cfvs_maniskill  # noqa: F401
    from cfvs_maniskill.control.executor import Executor
    from cfvs_maniskill.episode import run_episode
    from cfvs_maniskill.policies.registry import make_agent

    torch.set_num_threads(args.threads)
    env = gym.make("PegInsert6DoF-v1", obs_mode="pointcloud", objects=["test"])
    u = env.unwrapped
    agent = make_agent("cfvs", env)
    fwd = {
        "OAKN": forward_ms(agent.oakn, int(agent.oakn_meta["points"]), args.repeats),
        "OPN": forward_ms(agent.opn, int(agent.opn_meta["points"]), args.repeats),
    }
    ex = Executor(env)
    run_episode(env, agent, ex, seed=0)  # warm-up: shader compile, caches
    render = Timer(u.get_obs)
    physics = Timer(u._step_action)
    network = {"oakn": Timer(agent.oakn.forward), "opn": Timer(agent.opn.forward)}
    u.get_obs, u._step_action = render, physics
    agent.oakn.forward, agent.opn.forward = network["oakn"], network["opn"]
    walls, servo, ok = [], [], 0
    for s in range(args.episodes):
        r = run_episode(env, agent, ex, seed=1000 + s)
        walls.append(r.wall_time_s)
        servo.append(r.servo_time_s)
        ok += r.success
    env.close()
    wall = sum(walls)
    net = sum(t.total for t in network.values())
    parts = {
        "render (camera + point cloud)": render.total,
        "physics (control + PhysX)": physics.total,
        "network (OAKN + OPN)": net,
    }
    parts["other (IK, preprocessing, bookkeeping)"] = wall - sum(parts.values())
    floor = render.total + physics.total
    lines = [
        f"{args.episodes} CFVS 6-DoF episodes (seeds 1000-{999 + args.episodes}, test objects, "
        f"{args.threads} torch thread): {ok}/{args.episodes} success, mean wall "
        f"{wall / args.episodes:.2f} s, mean simulated servo time {np.mean(servo):.2f} s, "
        f"{physics.calls / args.episodes:.0f} control steps per episode. The networks' share"
        " is mostly OPN: one prediction per fine step far from the pose (vote_gate), three"
        " near it (the first, then a batch of two).",
        "",
        "| share of the episode wall time | seconds / episode | % |",
        "|---|---|---|",
        *[f"| {k} | {v / args.episodes:.3f} | {100 * v / wall:.0f}% |" for k, v in parts.items()],
    ]
    figures = [
        Figure(
            "CFVS 6-DoF episode wall time / its render + physics time",
            f"{wall / floor:.2f}",
            "<= 2.0",
            wall / floor <= 2.0,
            f"{wall / args.episodes:.2f} s vs {floor / args.episodes:.2f} s per episode",
        ),
        *[
            Figure(
                f"{k} forward, B=1, default points, 1 thread", f"{v:.1f} ms", "<= 20 ms", v <= 20
            )
            for k, v in fwd.items()
        ],
    ]
    return figures, "\n".join(lines)


def main(args: Args) -> None:
    figures, detail = measure(args)
    print("\n".join([detail, "", *[f.row() for f in figures]]))


if __name__ == "__main__":
    main(tyro.cli(Args))
