"""What the controller may do with the arm: the robot interface of a real cell's controller
(read the tool pose and joints, solve IK, command one control step, read the tared wrist
force/torque sensor, take one camera observation) and its simulated implementation."""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np
import torch

from cfvs_maniskill.robots.collision import ArmCollision


@runtime_checkable
class Robot(Protocol):
    dt: float
    """Control period, s."""
    clearance: float
    """The task's nominal hole clearance, m (the insertion chooses its mode by it)."""
    chamfer: float
    """The peg's chamfer, m."""
    peg: str
    """The peg's profile (round, square): the camera sees it, the known world leaves it out."""
    joint_limits: tuple[np.ndarray, np.ndarray]
    collision: ArmCollision
    """The arm's and peg's collision hulls (from its URDF), posed by forward kinematics."""

    def tcp(self) -> np.ndarray:
        """The tool (peg tip) pose, world, from the joints (forward kinematics)."""

    def joints(self) -> np.ndarray:
        """The joint positions, rad."""

    def ik(self, T: np.ndarray, seed: np.ndarray) -> tuple[np.ndarray, bool]:
        """Joint positions putting the tool at T, searched from `seed`; ok flag."""

    def command(self, q: np.ndarray, qd: np.ndarray | None = None) -> None:
        """One control step towards joint positions q (velocity feed-forward qd)."""

    def tare(self) -> None:
        """Take the wrist sensor's current reading as its zero (the peg is in free air)."""

    def wrench(self) -> np.ndarray:
        """The wrist force/torque reading since the last tare: (fx fy fz tx ty tz), flange
        frame, about the flange, N and N m."""

    def observe(self) -> Any:
        """One observation of the wrist camera, where the arm is now."""


class SimRobot:
    """The Robot interface on a PegInsertEnv (or a gym wrapper of one): steps skip the
    observation (no agent looks during a move), so only `observe` renders."""

    def __init__(self, env):
        self.gym_env = env
        self.env = env.unwrapped
        self.dt = 1.0 / self.env.control_freq
        self.clearance = self.env.task.clearance
        self.chamfer = self.env.task.peg_chamfer
        self.peg = self.env.task.peg
        self.joint_limits = self.env.kinematics.qlimits
        self.collision = self.env.collision
        self.last_info: dict = {}
        self._zero = np.zeros(6)

    def tcp(self) -> np.ndarray:
        return self.env.tcp_matrix()

    def joints(self) -> np.ndarray:
        return self.env.agent.robot.get_qpos()[0].cpu().numpy()

    def ik(self, T: np.ndarray, seed: np.ndarray) -> tuple[np.ndarray, bool]:
        return self.env.ik(T, seed)

    def command(self, q: np.ndarray, qd: np.ndarray | None = None) -> None:
        self._check_finite()  # PhysX with exact contacts crashes when stepped from NaN
        if self.env.control_mode == "pd_joint_pos_vel":
            qd = np.zeros_like(q) if qd is None else qd
            action = torch.as_tensor(np.concatenate([q, qd]), dtype=torch.float32)[None]
        else:
            action = torch.as_tensor(q, dtype=torch.float32)[None]
        self.env.defer_obs = True
        try:
            _, _, _, _, self.last_info = self.gym_env.step(action)
        finally:
            self.env.defer_obs = False
        self._check_finite()  # where a blow-up is made: named even on the last step

    def _check_finite(self) -> None:
        """Before each step too: a state set from outside the step can be non-finite."""
        qvel = self.env.agent.robot.get_qvel()[0].cpu().numpy()
        if not (np.all(np.isfinite(self.joints())) and np.all(np.isfinite(qvel))):
            raise FloatingPointError("simulation state became NaN")

    def tare(self) -> None:
        self._zero = self.env.wrist_wrench()

    def wrench(self) -> np.ndarray:
        return self.env.wrist_wrench() - self._zero

    def observe(self) -> Any:
        return self.env.get_obs()
