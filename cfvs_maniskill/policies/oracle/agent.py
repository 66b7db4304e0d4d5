"""The oracle: reads the true hole pose. The ceiling of every agent and proof of solvability."""

from __future__ import annotations

from cfvs_maniskill.constants import PRE_INSERT_HEIGHT
from cfvs_maniskill.policies.base import Action, Agent, Observation


class OracleAgent(Agent):
    """Move to the true pre-insertion pose, then insert."""

    name = "oracle"
    obs_mode = "state"  # sees nothing: its executor is handed the true object (episode.py)
    privileged = True

    def __init__(self, env):
        self.env = env.unwrapped
        self._moved = False

    def reset(self, seed: int) -> None:
        self._moved = False

    def act(self, observation: Observation) -> Action:
        if not self._moved:
            self._moved = True
            return Action.move(self.env.insertion_pose(-PRE_INSERT_HEIGHT))
        return Action.insert()
