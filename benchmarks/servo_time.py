"""Simulated servo time of CFVS on 3-DoF at 15 and 30 cm (the paper's Table III: 7.0 /
7.1 s), successes only, on the unseen test objects."""

from __future__ import annotations

import numpy as np

from benchmarks.common import Figure


def measure(episodes: int = 20) -> tuple[list[Figure], str]:
    import gymnasium as gym
    import torch

    from cfvs_maniskill.control.executor import Executor
    from cfvs_maniskill.episode import run_episode
    from cfvs_maniskill.policies.registry import make_agent

    torch.set_num_threads(1)
    env = gym.make("PegInsert3DoF-v1", obs_mode="pointcloud", objects=["test"])
    u = env.unwrapped
    agent, ex = make_agent("cfvs", env), Executor(env)
    figures, lines = [], []
    for err, paper in (("small", 7.0), ("large", 7.1)):
        u.init_error_m = u.task.init_error[err]
        res = [run_episode(env, agent, ex, seed=5000 + i) for i in range(episodes)]
        ok = [r for r in res if r.success]
        t = float(np.mean([r.servo_time_s for r in ok])) if ok else float("nan")
        steps = float(np.mean([r.steps for r in ok])) if ok else float("nan")
        figures.append(
            Figure(
                f"simulated servo time, CFVS 3-DoF {100 * u.init_error_m:.0f} cm (paper {paper} s)",
                f"{t:.2f} s",
                "<= 4 s",
                t <= 4.0,
                f"{len(ok)}/{episodes} success, {steps:.0f} control steps of 50 ms",
            )
        )
        lines.append(f"- {err}: {len(ok)}/{episodes} success, mean servo time {t:.2f} s")
    env.close()
    return figures, f"CFVS 3-DoF, seeds 5000-{4999 + episodes}, test objects:\n" + "\n".join(lines)
