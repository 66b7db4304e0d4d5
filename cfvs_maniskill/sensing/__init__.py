"""Sensor models: named profiles (`sensors/*.yaml`) of the wrist depth camera, its hand-eye
calibration and the wrist force/torque sensor, applied to what the simulator renders."""
