"""Policies ("agents" in this project; the robot is in `robots/`) and the shared executor."""
