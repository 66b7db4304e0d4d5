"""The one small interface every agent implements, and the episode loop that drives it."""

from __future__ import annotations

import abc
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class Action:
    """What an agent asks for: a target tcp pose, or to insert, or to give up."""

    kind: str  # "move" | "insert" | "give_up"
    pose: np.ndarray | None = None
    """4x4 world pose of the peg tip frame (z along the peg) for "move"."""
    reason: str = ""

    @staticmethod
    def move(pose: np.ndarray) -> Action:
        return Action("move", pose=np.asarray(pose, dtype=np.float64))

    @staticmethod
    def insert() -> Action:
        return Action("insert")

    @staticmethod
    def give_up(reason: str) -> Action:
        return Action("give_up", reason=reason)


@dataclass
class Observation:
    """What an agent sees each decision: the env's observation plus the tcp pose."""

    obs: Any
    tcp_pose: np.ndarray
    info: dict = field(default_factory=dict)


class Agent(abc.ABC):
    """reset(info) at the start of an episode; act(observation) until it says insert."""

    name: str = "agent"
    obs_mode: str = "pointcloud"
    """The ManiSkill obs mode this agent needs."""
    max_decisions: int = 30

    def reset(self, info: dict) -> None:  # noqa: B027  (optional hook)
        """Called once per episode with the env's episode info (object name, ...)."""

    @abc.abstractmethod
    def act(self, observation: Observation) -> Action: ...
