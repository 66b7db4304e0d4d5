"""Robots (ManiSkill "agents"): the UR5 with a peg on its flange and a wrist camera.

The robot classes load ManiSkill, so they are imported on first use: the light geometry
beside them (mounts, poses, kinematics tables) stays importable without the simulator.
"""

from __future__ import annotations

from typing import Any

__all__ = ["UR5RoundPeg", "UR5SquarePeg", "robot_uid_for"]


def __getattr__(name: str) -> Any:
    if name in __all__:
        from cfvs_maniskill.robots import ur5

        return getattr(ur5, name)
    raise AttributeError(f"module 'cfvs_maniskill.robots' has no attribute {name!r}")
