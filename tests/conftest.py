"""Shared fixtures. All env tests run in this one pytest process, so the renderer's shader
compile (first frame) happens once for the whole suite."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

import cfvs_maniskill  # noqa: F401  (registers the env ids)

ROOT = Path(__file__).resolve().parent.parent


def pytest_collection_modifyitems(config, items):
    """Slow tests first: under pytest-xdist (scripts/test.sh runs two workers) the long
    ones then overlap with the many short ones instead of ending the run alone."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


@pytest.fixture(scope="session")
def make_env():
    """Cached gym.make: one env per distinct argument set for the whole session."""
    import gymnasium as gym

    cache: dict = {}

    def make(env_id: str, **kwargs):
        key = (env_id, tuple(sorted((k, str(v)) for k, v in kwargs.items())))
        if key not in cache:
            cache[key] = gym.make(env_id, **kwargs)
        return cache[key]

    yield make
    for env in cache.values():
        env.close()


def run_cli(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    """Run `python -m <args>` as a user would, from the repository root."""
    return subprocess.run(
        [sys.executable, "-m", *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout
    )


def quiet(stderr: str) -> bool:
    """Only progress bars: no driver or library warnings on the user's terminal."""
    lines = [x for x in re.split(r"[\r\n]", stderr) if x.strip()]
    return not [x for x in lines if re.search(r"warn|error|unsupported", x, re.IGNORECASE)]


def held_out_outcomes(
    make_env,
    env_id: str,
    folder: str,
    obj: str,
    seed: int,
    configs: dict,
    init_error=None,
    **env_kwargs,
) -> dict:
    """(success, reason, lateral mm off the pre-insertion pose after the agent's last move)
    of one scene on held-out object `obj` (from `assets/<folder>`) for each CFVS agent of
    `configs` (label -> CFVSConfig keyword arguments): a paired comparison on the same env
    and seed."""
    from cfvs_maniskill.control.executor import Executor
    from cfvs_maniskill.episode import run_episode
    from cfvs_maniskill.policies.cfvs.agent import CFVSAgent
    from cfvs_maniskill.policies.cfvs.config import CFVSConfig
    from cfvs_maniskill.policies.interface import TaskSpec

    assets = str(ROOT / "assets" / folder)
    env = make_env(env_id, obs_mode="pointcloud", objects=(obj,), assets=(assets,), **env_kwargs)
    if init_error is not None:
        env.unwrapped.init_error_m = env.unwrapped.task.init_error[init_error]
    ex = Executor(env)
    out = {}
    for label, kwargs in configs.items():
        agent = CFVSAgent(TaskSpec.of_env(env), CFVSConfig(**kwargs))
        r = run_episode(env, agent, ex, seed=seed)
        last = r.move_residuals[-1][0] if r.move_residuals else float("inf")
        out[label] = (r.success, r.reason, last)
    return out
