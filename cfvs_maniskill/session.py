"""One place that builds what an episode needs: the task's env (with the options the agent
needs), the agent and the controller that executes its moves. The run command, the
evaluation workers, the report's video replays and the KOVIS diagnosis all build them here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from cfvs_maniskill.constants import DEFAULT_SEARCH_RADIUS
from cfvs_maniskill.envs.task_config import TaskConfig


def make_env(
    task: str | TaskConfig,
    agent: str,
    *,
    objects: list[str] | tuple[str, ...] | None = None,
    assets: list[str] | tuple[str, ...] = (),
    sensor: str = "ideal",
    **options: Any,
):
    """The env of `task` (a name, env id, task file or TaskConfig) for `agent`: the observation mode
    and env options the agent needs (registry.agent_env_kwargs), the hole objects (None:
    the task's list) and the sensor profile (a name or a file); `options` go to gym.make."""
    import gymnasium as gym

    from cfvs_maniskill.envs.lookup import find_task, make_args
    from cfvs_maniskill.policies.registry import agent_env_kwargs

    env_id, task_kwargs = make_args(task if isinstance(task, TaskConfig) else find_task(task))
    return gym.make(
        env_id,
        **task_kwargs,
        **agent_env_kwargs(agent),
        objects=None if objects is None else list(objects),
        assets=[str(a) for a in assets],
        sensor=sensor,
        **options,
    )


@dataclass
class Session:
    """An env, an agent on it and the controller that executes its moves."""

    env: Any
    agent: Any
    executor: Any

    def episode(self, seed: int, options: dict | None = None, film=None):
        """One episode -> its EpisodeResult."""
        from cfvs_maniskill.episode import run_episode

        return run_episode(self.env, self.agent, self.executor, seed, options=options, film=film)


def open_session(env, agent: str, search_radius: float = DEFAULT_SEARCH_RADIUS) -> Session:
    """The agent `agent` (a registry name, `cfvs@DIR` or `package.module:Class`) and a
    controller with this compliant-search radius, on `env` (from `make_env`)."""
    from cfvs_maniskill.control.executor import Executor, ExecutorConfig
    from cfvs_maniskill.policies.registry import make_agent

    executor = Executor(env, ExecutorConfig(search_radius=search_radius))
    return Session(env, make_agent(agent, env), executor)
