"""Robots (ManiSkill "agents"): the UR5 with a peg on its flange and a wrist camera."""

from cfvs_maniskill.robots.ur5 import UR5RoundPeg, UR5SquarePeg, robot_uid_for

__all__ = ["UR5RoundPeg", "UR5SquarePeg", "robot_uid_for"]
