"""The KOVIS baseline (Puang et al. 2020): closed-loop servoing on learned keypoints of the
wrist camera's stereo pair, step by step until the speed says "arrived", then insertion.

Each decision: both grey images -> keypoints -> the converter's unit motion direction
(tool frame, the task's degrees of freedom) and speed s in (0, 1), trained as
1 - exp(-a_dist * distance). KOVIS drives the robot at velocity s * v_max along the
direction and stops once s has stayed below a threshold for a few frames
(inference_oja.py: `speed - thresholds[0]`, `cnt_end > thresholds[1]`). Here a decision is
a move, not a velocity held for a frame: the move's length is the distance the speed
implies, -ln(1 - s) / a_dist (its own training target inverted), times a gain and at most
`max_step`. Near the goal this is KOVIS's velocity law at v_max * dt = 1 / a_dist; far
away it takes longer strides than a 10 Hz velocity loop would between two images. In 3 /
4-DoF tasks the peg is first turned to point straight down where it is (KOVIS aligns the
tool perpendicular first too: `move_tcp_perpendicular`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from cfvs_maniskill import resources
from cfvs_maniskill.nets.checkpoint import WeightsError
from cfvs_maniskill.perception import labels as L
from cfvs_maniskill.perception.images import normalise, stereo_images
from cfvs_maniskill.policies.base import Action, Agent, Observation
from cfvs_maniskill.policies.interface import TaskSpec
from cfvs_maniskill.policies.kovis.model import MOTION_DIMS, implied_distance
from cfvs_maniskill.policies.networks import load_weights
from cfvs_maniskill.task_dof import constrain

WEIGHTS_DIR = resources.bundled("agents") / "kovis"


@dataclass
class KOVISAgentConfig:
    weights_dir: Path = WEIGHTS_DIR
    """Folder with `<peg>.pt` (round.pt, square.pt)."""
    stop_speed: float = 0.25
    """Arrived when the speed stays below this (KOVIS's thresholds[0]); 0.25 means about
    1.4 mm to go at a_dist 200."""
    stop_count: int = 2
    """... for this many decisions in a row (KOVIS's thresholds[1], counted in frames)."""
    max_step: float = 0.02
    """Longest move per decision, m (rotation counted at the converter's rot_mul)."""
    gain: float = 0.8
    """Fraction of the implied distance moved per decision (a visual servo's lambda)."""
    max_steps: int = 40
    """Servo decisions before inserting anyway (KOVIS servoes for a set duration); 30 cm
    takes 15 at the longest move."""


MOUNT = "flange_side"
"""KOVIS's networks learn the images of one camera mount (agents/kovis/ on this one): its
data are collected there and it runs there, whatever mount the sensor profile names."""


class KOVISAgent(Agent):
    name = "kovis"
    obs_mode = "rgbd"
    env_options = {"stereo": True, "camera_mount": MOUNT}  # noqa: RUF012

    def __init__(self, task: TaskSpec, cfg: KOVISAgentConfig | None = None):
        self.task = task
        self.cfg = cfg or KOVISAgentConfig()
        peg = task.peg
        self.net, self.meta = load_weights(self.cfg.weights_dir / f"{peg}.pt", "kovis", peg)
        if self.net.cfg.motion_dims < task.dof:
            raise WeightsError(
                f"{self.cfg.weights_dir / f'{peg}.pt'}: field 'config.motion_dims': the net "
                f"drives {self.net.cfg.motion_dims} DoF, task {task.name} needs {task.dof}"
            )
        self.max_decisions = self.cfg.max_steps + 2
        self.reset(0)

    def reset(self, seed: int) -> None:
        self.steps = 0
        self.upright = self.task.dof == 6
        self.low = 0
        self.phase, self.estimate = "", None

    @torch.no_grad()
    def motion(self, obs: dict) -> tuple[np.ndarray, float]:
        """(tool-frame action (dt, dr) of one servo decision, the speed s)."""
        x = normalise(torch.from_numpy(stereo_images(obs, self.net.cfg.image)))[None]
        out = self.net(x[:, :1], x[:, 1:], decode=False)
        cfg = self.net.cfg
        s = float(torch.sigmoid(out["speed"][0]))
        length = min(self.cfg.gain * implied_distance(s, cfg), self.cfg.max_step)
        step = out["direction"][0].numpy().astype(np.float64) * length
        dims = MOTION_DIMS[cfg.motion_dims]
        action = np.zeros(6)
        action[dims] = step
        action[3:] *= cfg.rot_mul  # the direction's rotation is in metres / rot_mul
        keep = MOTION_DIMS[self.task.dof]  # a 6-D net serving a 4-DoF task keeps its yaw
        action[[i for i in range(6) if i not in keep]] = 0.0
        return action, s

    def act(self, observation: Observation) -> Action:
        tcp = observation.tcp_pose
        if not self.upright:
            self.upright = True
            self.phase = "align the tool"
            return Action.move(constrain(self.task, tcp, ref=tcp))
        if self.steps >= self.cfg.max_steps:
            self.phase = "insert (servo time out)"
            return Action.insert()
        action, s = self.motion(observation.obs)
        if not np.all(np.isfinite(action)):
            return Action.give_up("KOVIS: the servo network returned a non-finite motion")
        self.low = self.low + 1 if s < self.cfg.stop_speed else 0
        if self.low >= self.cfg.stop_count:
            self.phase = f"insert (speed {s:.2f})"
            return Action.insert()
        self.steps += 1
        self.phase = f"servo step {self.steps} (speed {s:.2f})"
        return Action.move(constrain(self.task, L.apply_action(tcp, action), ref=tcp))
