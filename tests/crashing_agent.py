"""An agent that kills its own process on its first decision, as a SAPIEN segfault or the
OOM killer would kill an eval worker (tests of the evaluation's crash handling)."""

from __future__ import annotations

import os
import signal

from cfvs_maniskill.agents.base import Action, Agent, Observation


class CrashingAgent(Agent):
    obs_mode = "state"  # no camera: a worker starts without compiling shaders

    def __init__(self, task):
        self.task = task

    def act(self, observation: Observation) -> Action:
        os.kill(os.getpid(), signal.SIGKILL)
        return Action.give_up("unreachable")
