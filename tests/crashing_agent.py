"""Agents that kill their own process (as a SAPIEN segfault or the OOM killer would kill an
eval worker) or never finish a decision: tests of the evaluation's crash handling."""

from __future__ import annotations

import os
import signal
import time

from cfvs_maniskill.policies.base import Action, Agent, Observation


class CrashingAgent(Agent):
    """Kills its own process on its first decision."""

    obs_mode = "state"  # no camera: a worker starts without compiling shaders

    def __init__(self, task):
        self.task = task

    def act(self, observation: Observation) -> Action:
        os.kill(os.getpid(), signal.SIGKILL)
        return Action.give_up("unreachable")


class StuckAgent(Agent):
    """An agent whose first decision takes ten minutes, as a worker stuck in a long
    computation would (tests that a killed evaluation does not leave it running)."""

    obs_mode = "state"

    def __init__(self, task):
        self.task = task

    def act(self, observation: Observation) -> Action:
        time.sleep(600)
        return Action.give_up("woke up")


class RaisingAgent(Agent):
    """A user agent with a bug in its decision."""

    obs_mode = "state"

    def __init__(self, task):
        self.task = task

    def act(self, observation: Observation) -> Action:
        return {}["no such key"]


class BrokenInitAgent(Agent):
    """A user agent whose constructor raises."""

    obs_mode = "state"

    def __init__(self, task):
        raise RuntimeError("cannot open the calibration file")

    def act(self, observation: Observation) -> Action:
        return Action.insert()


class NoneAgent(Agent):
    """A user agent that forgets to return its action."""

    obs_mode = "state"

    def __init__(self, task):
        self.task = task

    def act(self, observation: Observation) -> Action:
        return None
