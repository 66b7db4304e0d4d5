"""Wrist stereo images for the image-based baseline (KOVIS), shared by collection and agent.

KOVIS sees the grey images of a stereo camera's two imagers (its authors: a RealSense
D435's infrared pair), cropped square and resized to its 96 x 96 input (`IMAGE_SIZE`).
Here both come from the env's lit stereo imagers (gym.make(..., stereo=True)), rendered at
the task's camera resolution and resized by area averaging. Collection also keeps each
imager's depth and segmentation, the decoder's self-supervision targets (never an input).
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from cfvs_maniskill.robots.ur5 import STEREO_UIDS
from cfvs_maniskill.sensing.surfaces import GREY

IMAGE_SIZE = 96
DEPTH_RANGE = (0.03, 0.5)
"""Depth is clipped to this range, metres (KOVIS's cam_clip); 0 (nothing seen) -> far."""
GRAY_MEAN, GRAY_STD = 0.41, 0.26
"""KOVIS's input normalisation of grey levels in [0, 1]."""
SEG_BACKGROUND, SEG_PEG, SEG_HOLE = 0, 1, 2
"""Segmentation classes of the decoder's target."""


def _resize(x: np.ndarray, side: int) -> np.ndarray:
    """(H, W) -> (side, side) by area averaging (a square image; any size)."""
    t = torch.from_numpy(np.ascontiguousarray(x, dtype=np.float32))[None, None]
    return F.interpolate(t, size=(side, side), mode="area")[0, 0].numpy()


def _check(uid: str, obs: dict) -> dict:
    data = obs.get("sensor_data", {}).get(uid)
    if data is None or "rgb" not in data:
        raise ValueError(
            f"the observation has no '{uid}' rgb image: make the env with stereo=True and an "
            "image obs mode (e.g. gym.make(env_id, obs_mode='rgbd', stereo=True))"
        )
    rgb = data["rgb"]
    if rgb.shape[1] != rgb.shape[2]:
        raise ValueError(
            f"wrist imager '{uid}' is {rgb.shape[2]}x{rgb.shape[1]}; KOVIS needs a square image "
            "(task fields camera_width / camera_height)"
        )
    return data


def stereo_images(obs: dict, side: int = IMAGE_SIZE) -> np.ndarray:
    """(2, side, side) uint8 grey images of the left and right imager."""
    out = []
    for uid in STEREO_UIDS:
        rgb = _check(uid, obs)["rgb"][0].cpu().numpy().astype(np.float32)
        gray = rgb @ GREY
        out.append(_resize(gray, side).round().clip(0, 255).astype(np.uint8))
    return np.stack(out)


def stereo_targets(obs: dict, seg_ids: dict[int, int], side: int = IMAGE_SIZE):
    """The decoder's targets per imager: depth (2, side, side) float16 metres, clipped to
    DEPTH_RANGE, and segmentation (2, side, side) uint8 classes (`seg_ids`: the scene's
    per-object ids -> SEG_PEG / SEG_HOLE; anything else is background)."""
    depths, segs = [], []
    for uid in STEREO_UIDS:
        data = _check(uid, obs)
        d = data["depth"][0, ..., 0].cpu().numpy().astype(np.float32) / 1000.0
        d = np.where(d <= 0, DEPTH_RANGE[1], d).clip(*DEPTH_RANGE)
        depths.append(_resize(d, side).astype(np.float16))
        ids = data["segmentation"][0, ..., 0].cpu().numpy()
        cls = np.zeros(ids.shape, np.uint8)
        for k, v in seg_ids.items():
            cls[ids == k] = v
        n = ids.shape[0]
        pick = (np.arange(side) * n) // side  # nearest: classes do not average
        segs.append(cls[np.ix_(pick, pick)])
    return np.stack(depths), np.stack(segs)


def normalise(gray: torch.Tensor) -> torch.Tensor:
    """(..., S, S) uint8 or float grey levels -> float, KOVIS's normalisation."""
    return (gray.float() / 255.0 - GRAY_MEAN) / GRAY_STD


def depth_normalise(depth: torch.Tensor) -> torch.Tensor:
    """Metres -> the decoder's depth target scale ((x - 0.5) / 0.25 of [0, 1] over
    DEPTH_RANGE, as KOVIS normalises its depth images)."""
    lo, hi = DEPTH_RANGE
    return ((depth.float() - lo) / (hi - lo) - 0.5) / 0.25
