"""Registers a gym env id for every task file (`<name>-v1`) and one for any task file."""

from __future__ import annotations

from mani_skill.utils.registration import register_env

from cfvs_maniskill.envs.peg_insert import PegInsertEnv
from cfvs_maniskill.envs.task_config import TaskConfig, load_tasks

GENERIC_ID = "PegInsert-v1"
"""The task of any task file: `gym.make(GENERIC_ID, task_file=PATH)`."""


def register_tasks() -> dict[str, TaskConfig]:
    """Register `<name>-v1` for every bundled task file and every one in the user folder,
    and GENERIC_ID for a task file given by path (idempotent)."""
    from mani_skill.utils.registration import REGISTERED_ENVS

    if GENERIC_ID not in REGISTERED_ENVS:
        cls = type("PegInsert", (PegInsertEnv,), {"__doc__": PegInsertEnv.__doc__})
        register_env(GENERIC_ID, max_episode_steps=None)(cls)
    tasks = load_tasks()
    for name, cfg in tasks.items():
        if cfg.env_id in REGISTERED_ENVS:
            continue
        cls = type(name, (PegInsertEnv,), {"task": cfg, "__doc__": PegInsertEnv.__doc__})
        register_env(cfg.env_id, max_episode_steps=cfg.max_episode_steps)(cls)
    return tasks


__all__ = ["GENERIC_ID", "register_tasks"]
