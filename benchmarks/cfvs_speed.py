"""CFVS speed on this CPU: network forward passes and a 6-DoF episode's wall time split
into render / physics / network / other. `python -m benchmarks.cfvs_speed`.

Writes the `cfvs_speed` section of benchmarks/RESULTS.md (other sections are kept).
"""

from __future__ import annotations

import platform
import statistics
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import tyro

RESULTS = Path(__file__).parent / "RESULTS.md"


@dataclass
class Args:
    """Time OAKN / OPN forward passes and full CFVS 6-DoF episodes."""

    episodes: int = 10
    """CFVS 6-DoF episodes to time."""
    repeats: int = 50
    """Forward passes per network (median reported)."""
    threads: int = 1
    """torch threads (an eval worker uses 1)."""


class Timer:
    """Wraps a callable and accumulates its wall time."""

    def __init__(self, fn):
        self.fn, self.total = fn, 0.0

    def __call__(self, *a, **k):
        t = time.perf_counter()
        try:
            return self.fn(*a, **k)
        finally:
            self.total += time.perf_counter() - t


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


def write_section(name: str, body: str) -> None:
    text = RESULTS.read_text() if RESULTS.exists() else "# Benchmark results\n"
    start, end = f"<!-- {name} -->", f"<!-- /{name} -->"
    block = f"{start}\n{body.rstrip()}\n{end}"
    if start in text:
        a, b = text.index(start), text.index(end) + len(end)
        text = text[:a] + block + text[b:]
    else:
        text = text.rstrip() + "\n\n" + block + "\n"
    RESULTS.write_text(text)


def main(args: Args) -> str:
    import gymnasium as gym

    import cfvs_maniskill  # noqa: F401
    from cfvs_maniskill.agents.cfvs import CFVSAgent
    from cfvs_maniskill.agents.executor import Executor
    from cfvs_maniskill.episode import run_episode

    torch.set_num_threads(args.threads)
    env = gym.make("PegInsert6DoF-v1", obs_mode="pointcloud")
    u = env.unwrapped
    agent = CFVSAgent(env)
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
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    lines = [
        "## CFVS speed (`python -m benchmarks.cfvs_speed`)",
        f"{time.strftime('%Y-%m-%d')}, commit {commit}, {platform.processor() or platform.machine()}, "
        f"{torch.get_num_threads()} torch thread(s), no GPU (SwiftShader rendering).",
        "",
        "| network (B=1, default points) | forward, median |",
        "|---|---|",
        *[f"| {k} | {v:.1f} ms |" for k, v in fwd.items()],
        "",
        f"{args.episodes} CFVS 6-DoF episodes (seeds 1000-{999 + args.episodes}, test objects): "
        f"{ok}/{args.episodes} success, mean wall {wall / args.episodes:.2f} s, "
        f"mean simulated servo time {np.mean(servo):.2f} s.",
        "",
        "| share of the episode wall time | seconds / episode | % |",
        "|---|---|---|",
        *[f"| {k} | {v / args.episodes:.3f} | {100 * v / wall:.0f}% |" for k, v in parts.items()],
    ]
    body = "\n".join(lines)
    write_section("cfvs_speed", body)
    print(body)
    return body


if __name__ == "__main__":
    main(tyro.cli(Args))
