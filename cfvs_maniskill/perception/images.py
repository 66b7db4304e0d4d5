"""Wrist-camera images for the image-based baseline (KOVIS), shared by collection and agent.

KOVIS sees a grayscale image and learns to reconstruct depth from it; both are taken from
the same wrist camera the point-cloud agents use (obs mode "rgbd") and halved to
IMAGE_SIZE by 2 x 2 averaging (cheap on a CPU, and the paper's KOVIS runs at 96 px).
"""

from __future__ import annotations

import numpy as np

from cfvs_maniskill.robots.ur5 import CAMERA_UID

IMAGE_SIZE = 64
DEPTH_RANGE = (0.03, 0.5)
"""Depth is clipped to this range, metres (KOVIS's cam_clip); 0 (nothing seen) -> far."""


def _halve(x: np.ndarray, factor: int) -> np.ndarray:
    h, w = x.shape
    return x.reshape(h // factor, factor, w // factor, factor).mean(axis=(1, 3))


def wrist_images(obs: dict) -> tuple[np.ndarray, np.ndarray]:
    """(gray uint8 (S, S), depth float32 metres (S, S)) from an rgbd observation."""
    cam = obs["sensor_data"][CAMERA_UID]
    rgb = cam["rgb"][0].cpu().numpy().astype(np.float32)
    depth = cam["depth"][0, ..., 0].cpu().numpy().astype(np.float32) / 1000.0
    depth = np.where(depth <= 0, DEPTH_RANGE[1], depth).clip(*DEPTH_RANGE)
    factor = rgb.shape[0] // IMAGE_SIZE
    if factor < 1 or rgb.shape[0] != rgb.shape[1] or rgb.shape[0] % IMAGE_SIZE:
        raise ValueError(
            f"wrist camera is {rgb.shape[1]}x{rgb.shape[0]}; KOVIS needs a square image whose "
            f"side is a multiple of {IMAGE_SIZE} (task fields camera_width / camera_height)"
        )
    gray = rgb @ np.array([0.299, 0.587, 0.114], dtype=np.float32)
    return _halve(gray, factor).round().astype(np.uint8), _halve(depth, factor).astype(np.float32)
