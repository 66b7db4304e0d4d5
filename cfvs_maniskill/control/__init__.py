"""Carrying out an agent's decisions on the arm: moves, the two insertions (position and
force-guided) and the spiral search they share, through the Robot interface (robot.py)."""
