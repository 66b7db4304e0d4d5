"""The KOVIS baseline (Puang et al. 2020): closed-loop image-based servoing on learned
keypoints, step by step until the converter says "arrived", then insertion.

Each decision: the wrist image -> keypoints -> a unit motion direction (tool frame, the
task's degrees of freedom) and a speed in (0, 1); the peg moves `speed * speed_range`
along the direction (so a far goal is approached in steps of at most `speed_range`).
It stops when the speed says the goal is within `stop_distance`, or when that predicted
distance has stopped shrinking (the servo circles the goal at its precision). In 3 / 4-DoF tasks the
peg is first turned to point straight down where it is (the servo was trained on upright
poses there), as every agent keeps the task's degrees of freedom.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from cfvs_maniskill.agents.base import Action, Agent, Observation
from cfvs_maniskill.agents.interface import TaskSpec
from cfvs_maniskill.constants import AGENTS_DIR
from cfvs_maniskill.nets.checkpoint import load_weights
from cfvs_maniskill.perception import labels as L
from cfvs_maniskill.perception.images import wrist_images
from cfvs_maniskill.task_dof import constrain

WEIGHTS_DIR = AGENTS_DIR / "kovis"
MOTION_DIMS = {3: [0, 1, 2], 4: [0, 1, 2, 5], 6: [0, 1, 2, 3, 4, 5]}
"""Which of (dx, dy, dz, rx, ry, rz) a converter with that many outputs drives."""


@dataclass
class KOVISAgentConfig:
    weights_dir: Path = WEIGHTS_DIR
    """Folder with `<peg>.pt` (round.pt, square.pt)."""
    stop_distance: float = 0.003
    """Arrived when the predicted distance (speed * speed_range) is below this, metres."""
    max_steps: int = 25
    """Servo steps before inserting anyway."""
    patience: int = 3
    """Also arrived when the predicted distance has not improved for this many steps: the
    servo is circling the goal at the limit of its precision."""
    gain: float = 0.6
    """Fraction of the predicted distance moved per step (a visual servo's lambda): a
    full step overshoots by the speed's error and runs the peg into the object."""


class KOVISAgent(Agent):
    name = "kovis"
    obs_mode = "rgbd"

    def __init__(self, task: TaskSpec, cfg: KOVISAgentConfig | None = None):
        self.task = task
        self.cfg = cfg or KOVISAgentConfig()
        peg = task.peg
        self.net, self.meta = load_weights(self.cfg.weights_dir / f"{peg}.pt", "kovis", peg)
        self.max_decisions = self.cfg.max_steps + 2
        self.steps = 0
        self.upright = False
        self.best, self.stalled = np.inf, 0

    def reset(self, seed: int) -> None:
        self.steps = 0
        self.upright = self.task.dof == 6
        self.best, self.stalled = np.inf, 0

    @torch.no_grad()
    def motion(self, obs: dict) -> tuple[np.ndarray, float]:
        """(tool-frame action (dt, dr) of one servo step, predicted distance to the goal)."""
        gray, _ = wrist_images(obs)
        _, _, direction, speed_logit = self.net(torch.from_numpy(gray)[None])
        cfg = self.net.cfg
        speed = float(torch.sigmoid(speed_logit[0]))
        step = direction[0].numpy().astype(np.float64) * speed * cfg.speed_range * self.cfg.gain
        action = np.zeros(6)
        action[MOTION_DIMS[cfg.motion_dims]] = step
        action[3:] /= cfg.rot_scale
        return action, speed * cfg.speed_range

    def act(self, observation: Observation) -> Action:
        tcp = observation.tcp_pose
        if not self.upright:
            self.upright = True
            return Action.move(constrain(self.task, tcp, ref=tcp))
        if self.steps >= self.cfg.max_steps:
            return Action.insert()
        action, distance = self.motion(observation.obs)
        if not np.all(np.isfinite(action)):
            return Action.give_up("KOVIS: the servo network returned a non-finite motion")
        self.stalled = 0 if distance < self.best else self.stalled + 1
        self.best = min(self.best, distance)
        if distance < self.cfg.stop_distance or self.stalled >= self.cfg.patience:
            return Action.insert()
        self.steps += 1
        return Action.move(constrain(self.task, L.apply_action(tcp, action), ref=tcp))
