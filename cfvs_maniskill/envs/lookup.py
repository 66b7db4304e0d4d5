"""A task by name, env id or task-file path -> its config and the `gym.make` call for it."""

from __future__ import annotations

from pathlib import Path

from cfvs_maniskill.envs.registration import GENERIC_ID, TASKS
from cfvs_maniskill.envs.task_config import INVALID, TaskConfig, TaskConfigError, load_task


class UnknownTaskError(ValueError):
    """A task name that is no registered task and no task file."""


def find_task(spec: str | Path) -> TaskConfig:
    """`PegInsert6DoF`, `PegInsert6DoF-v1` (bundled or in the user folder) or a task file's
    path. A file named like a registered task must hold the same task: its records would
    otherwise be counted as that task's."""
    from cfvs_maniskill.provenance import sha256

    base = str(spec).removesuffix("-v1")
    if base in TASKS:
        return TASKS[base]
    if base in INVALID:
        raise INVALID[base]
    path = Path(spec).expanduser()
    if path.suffix not in (".yaml", ".yml") and not path.exists():
        raise UnknownTaskError(
            f"unknown task '{spec}'; valid: {', '.join(sorted(TASKS))}, or a path to a task "
            "file (.yaml)"
        )
    if not path.is_file():
        raise TaskConfigError(path, "<file>", "no such task file")
    cfg = load_task(path)
    registered = TASKS.get(cfg.name)
    if registered is None:
        return cfg
    if sha256(registered.source) != sha256(path):
        raise TaskConfigError(
            path,
            "<file>",
            f"named like the task '{cfg.name}' ({registered.source}) but not the same "
            "file: give it a name of its own, so that its records are not taken for that "
            "task's",
        )
    return registered


def make_args(cfg: TaskConfig) -> tuple[str, dict]:
    """The env id and keywords that `gym.make` builds `cfg`'s env with."""
    if TASKS.get(cfg.name) is cfg:
        return cfg.env_id, {}
    return GENERIC_ID, {"task_file": cfg.source, "max_episode_steps": cfg.max_episode_steps}


def recorded_file(rec: dict, kind: str) -> str | None:
    """The file a result record's provenance names for `kind` ("task", "sensor")."""
    return ((rec.get("provenance") or {}).get(kind) or {}).get("file")


def task_named(name: str, file: str | None) -> TaskConfig:
    """A recorded task: its registered name, else its file (a task given by path)."""
    try:
        return find_task(name)
    except UnknownTaskError:
        if not file or not Path(file).is_file():
            raise
        return find_task(file)


def task_of_record(rec: dict) -> TaskConfig:
    """The task a result record was made on (`task_named`)."""
    return task_named(rec["task"], recorded_file(rec, "task"))


def sensor_of_record(rec: dict) -> str:
    """The sensor profile a record was made with: its name, else the profile file its
    provenance names (a profile given by path)."""
    from cfvs_maniskill.sensing.profile import available_profiles

    name = rec.get("sensor", "ideal")
    file = recorded_file(rec, "sensor")
    if name in available_profiles() or not file or not Path(file).is_file():
        return name
    return file
