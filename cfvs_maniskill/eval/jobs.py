"""The job list of an evaluation: one fixed-seed episode per (task, agent, object, initial
error, episode index)."""

from __future__ import annotations

import zlib
from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class Job:
    task: str
    agent: str
    object: str
    init_error: str
    episode: int
    seed: int
    sensor: str = "ideal"

    @property
    def key(self) -> str:
        return job_key(
            self.task, self.agent, self.object, self.init_error, self.episode, self.sensor
        )

    def to_json(self) -> dict:
        return asdict(self)


def job_key(
    task: str, agent: str, obj: str, init_error: str, episode: int, sensor: str = "ideal"
) -> str:
    """Records made before sensor profiles existed are `ideal` ones and keep their keys."""
    key = f"{task}|{agent}|{obj}|{init_error}|{episode}"
    return key if sensor == "ideal" else f"{key}|{sensor}"


def scene_seed(task: str, obj: str, init_error: str, episode: int, base: int) -> int:
    """The env seed of an episode: the same scene for every agent (paired comparison), a
    stable hash (not Python's salted hash()) so every process and machine agrees."""
    return zlib.crc32(f"{task}|{obj}|{init_error}|{episode}|{base}".encode()) & 0x7FFFFFFF


def make_jobs(
    tasks: dict[str, list[str]],
    agents: list[str],
    init_errors: list[str],
    episodes_per_object: int,
    base_seed: int,
    sensors: list[str] = ("ideal",),
) -> list[Job]:
    """`tasks` maps each task to its objects. Ordered sensor, task, agent, object, error,
    episode, so that consecutive jobs share an env and an agent. A scene's seed does not
    depend on the sensor: every profile sees the same scenes."""
    return [
        Job(t, a, o, e, i, scene_seed(t, o, e, i, base_seed), s)
        for s in sensors
        for t, objects in tasks.items()
        for a in agents
        for o in objects
        for e in init_errors
        for i in range(episodes_per_object)
    ]
