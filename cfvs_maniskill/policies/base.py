"""The one small interface every agent implements, and the episode loop that drives it."""

from __future__ import annotations

import abc
from collections.abc import Callable
from dataclasses import dataclass, field

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
    """What an agent sees each decision: what a robot's own sensors report (interface.py)."""

    obs: dict
    """`robot_view` of the env's observation: the wrist cloud or wrist images only."""
    tcp_pose: np.ndarray
    """4x4 world pose of the peg tip frame, by forward kinematics of the joint angles."""
    qpos: np.ndarray = field(default_factory=lambda: np.zeros(6))
    """Joint angles, rad."""
    wrench: np.ndarray = field(default_factory=lambda: np.zeros(6))
    """Wrist force/torque sensor: (fx, fy, fz, tx, ty, tz) in the flange frame, N and N m."""


class Agent(abc.ABC):
    """Built from a `TaskSpec`; reset(seed) at the start of an episode; act(observation)
    until it says insert."""

    name: str = "agent"
    obs_mode: str = "pointcloud"
    """The ManiSkill obs mode this agent needs."""
    env_options: dict = {}  # noqa: RUF012  (read-only: a class-level default)
    """Other gym.make keywords the agent needs, e.g. {"stereo": True} for the wrist
    camera's stereo pair of lit grey images."""
    max_decisions: int = 30
    privileged: bool = False
    """True only for the oracle, which is handed the env and reads true poses."""
    weights: dict[str, str] = {}  # noqa: RUF012  (replaced per agent by make_agent)
    """The weights files the agent loaded -> their sha256 (records' provenance)."""
    phase: str = ""
    """What the last `act` did (e.g. "coarse (OAKN)"): the record's `decisions` and the
    videos' captions."""
    estimate: np.ndarray | None = None
    """For videos only: the agent's current estimate of the hole frame (4x4, world; origin
    at the opening's centre, z out of the hole), drawn into the wrist view; None: none."""

    def reset(self, seed: int) -> None:  # noqa: B027  (optional hook)
        """Called once per episode with a seed for the agent's own randomness, derived from
        (never equal to) the env's seed: the same episode gives the same seed."""

    @abc.abstractmethod
    def act(self, observation: Observation) -> Action: ...


ACTION_KINDS = ("move", "insert", "give_up")


class AgentFailure(Exception):
    """An agent that raised, or returned something that is not an action: its episode fails
    with this as the reason and the evaluation goes on. `decision`: 0 when it was built or
    reset, else which of its decisions (1-based)."""

    def __init__(self, agent: str, decision: int, kind: str, message: str):
        self.agent, self.decision, self.kind, self.message = agent, decision, kind, message
        where = "before its first decision" if decision == 0 else f"at decision {decision}"
        super().__init__(f"agent {agent} failed {where}: {kind}: {message}")

    def __reduce__(self):  # crosses the pipe from an eval worker intact
        return type(self), (self.agent, self.decision, self.kind, self.message)

    def to_json(self) -> dict:
        return {
            "agent": self.agent,
            "decision": self.decision,
            "type": self.kind,
            "message": self.message[:500],
        }

    @classmethod
    def of(cls, agent: str, decision: int, e: BaseException) -> AgentFailure:
        return cls(agent, decision, type(e).__name__, str(e))


def checked_action(action, agent: str, decision: int):
    """`action` if it is one the executor can carry out, else AgentFailure saying what it is."""
    if not isinstance(action, Action):
        raise AgentFailure(
            agent, decision, "MalformedAction", f"returned {action!r:.80}, not an Action"
        )
    if action.kind not in ACTION_KINDS:
        raise AgentFailure(
            agent,
            decision,
            "MalformedAction",
            f"action kind {action.kind!r}; expected one of {', '.join(ACTION_KINDS)}",
        )
    if action.kind == "move":
        pose = None if action.pose is None else np.asarray(action.pose)
        if pose is None or pose.shape != (4, 4) or not np.issubdtype(pose.dtype, np.number):
            got = "no pose" if pose is None else f"a pose of shape {pose.shape} ({pose.dtype})"
            raise AgentFailure(agent, decision, "MalformedAction", f"move with {got}, expected 4x4")
        if not np.all(np.isfinite(pose)):
            raise AgentFailure(agent, decision, "MalformedAction", "returned a non-finite pose")
    return action


@dataclass(frozen=True)
class AgentEntry:
    """An agent name's class and factory, as a policy folder declares it (its `AGENTS`)."""

    cls: str
    """`module:Class`: its `obs_mode` and `env_options` say what the env must give it."""
    make: Callable[..., Agent]
    """Builds the agent from the task's TaskSpec (from the env if `privileged`)."""
    privileged: bool = False
    """Takes the env itself and reads the truth (the oracle): a ceiling, not an agent."""
