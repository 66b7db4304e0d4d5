"""Policies ("agents" in this project; the robot is in `robots/`, the controller that carries
out their decisions in `control/`)."""
