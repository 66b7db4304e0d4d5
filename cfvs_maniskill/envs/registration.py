"""Registers a gym env id for every task file (`<name>-v1`) and one for any task file.

Registering is light: gym keeps a factory per id, and the simulator (ManiSkill, SAPIEN,
torch) and the rendering device are loaded when an env is first made, so that reading
records, tasks and reports never needs a renderer."""

from __future__ import annotations

from functools import partial

import gymnasium as gym
from gymnasium.envs.registration import WrapperSpec

from cfvs_maniskill.envs.task_config import TaskConfig, load_tasks

GENERIC_ID = "PegInsert-v1"
"""The task of any task file: `gym.make(GENERIC_ID, task_file=PATH)`."""
TASKS: dict[str, TaskConfig] = {}
"""The registered tasks by name (filled by `register_tasks`)."""


def register_tasks() -> dict[str, TaskConfig]:
    """Register `<name>-v1` for every bundled task file and every one in the user folder,
    and GENERIC_ID for a task file given by path (idempotent)."""
    TASKS.update(load_tasks())
    ids = [(GENERIC_ID, None)] + [(c.env_id, c.max_episode_steps) for c in TASKS.values()]
    for env_id, steps in ids:
        if env_id not in gym.registry:
            _register(env_id, steps)
    return TASKS


def _register(env_id: str, max_episode_steps: int | None) -> None:
    # The same registration as ManiSkill's `register_env`, with factories that import late.
    gym.register(
        env_id,
        entry_point=partial(make_env, env_id),
        vector_entry_point=partial(make_vector_env, env_id),
        max_episode_steps=max_episode_steps,
        disable_env_checker=True,  # ManiSkill's observation spaces may be empty
        additional_wrappers=(
            WrapperSpec(
                "MSTimeLimit",
                entry_point="mani_skill.utils.registration:TimeLimitWrapper",
                kwargs={"max_episode_steps": max_episode_steps},
            ),
        ),
    )


def make_env(env_id: str, **kwargs):
    """gym's entry point: picks the rendering device (one clear error if there is none),
    then builds the env class for `env_id` and registers it with ManiSkill too."""
    from cfvs_maniskill.rendering import device

    device.render_backend(kwargs.get("render_backend"))  # raises RenderDeviceError first
    from mani_skill.utils.registration import REGISTERED_ENVS, register

    from cfvs_maniskill.envs.peg_insert import PegInsertEnv

    if env_id not in REGISTERED_ENVS:
        task = next((t for t in TASKS.values() if t.env_id == env_id), None)
        name = task.name if task else GENERIC_ID.removesuffix("-v1")
        cls = type(name, (PegInsertEnv,), {"task": task, "__doc__": PegInsertEnv.__doc__})
        register(env_id, cls, max_episode_steps=gym.spec(env_id).max_episode_steps)
    with device.driver_output_to_log():
        return REGISTERED_ENVS[env_id].make(**kwargs)


def make_vector_env(env_id: str, **kwargs):
    """gym's vector entry point, as ManiSkill's: the env in ManiSkill's vector wrapper."""
    from mani_skill.vector.wrappers.gymnasium import ManiSkillVectorEnv

    return ManiSkillVectorEnv(gym.make(env_id, **kwargs))


__all__ = ["GENERIC_ID", "TASKS", "make_env", "register_tasks"]
