"""How much texture each surface of the scene gives a stereo matcher.

A passive stereo camera (the D405 has no projector) matches the fine texture of what it
sees; a plain part returns fewer pixels and noisier ones than a printed one. Texture is a
property of the surface: each hole object names its `material` (or a `texture` number) in
its file, the table and the robot have theirs here. The number is the RMS contrast of the
surface's fine texture at the matcher's scale, as a fraction of its brightness; the stereo
model (`sensing/depth.py`) multiplies it by the surface's albedo and the cosine of the
view's incidence and compares it with the imagers' noise (docs/sensing.md).
"""

from __future__ import annotations

import numpy as np

MATERIALS: dict[str, float] = {
    # A mid-grey (albedo 0.6) plain part seen square-on then matches with 2.5x the noise of
    # a textured target, as D405 users report on low-texture surfaces (librealsense #11219:
    # 1.5 mm spread at 25 cm where the textured figure is 0.62 mm); 73% of its pixels return
    # (results/texture_study).
    "plain": 0.005,
    # Assumed: tool marks and grain of milled or blasted metal.
    "machined": 0.02,
    # Assumed: a wooden bench top's grain.
    "wood": 0.05,
    # A printed random pattern, Intel's target for testing passive stereo (RealSense Camera
    # Depth Testing Methodology, 2018, Fig. 1-2): matched at the camera's noise floor.
    "printed": 0.2,
}
"""Texture contrast per material."""

DEFAULT_PART_MATERIAL = "plain"
"""A hole object whose file names no material: our bodies are plain single-colour parts."""
TABLE_MATERIAL = "wood"
ROBOT_MATERIAL = "plain"
"""The arm's painted links."""
PEG_MATERIAL = "machined"


GREY = np.array([0.299, 0.587, 0.114], dtype=np.float32)
"""Luma weights (ITU-R BT.601): an RGB colour's grey level."""


def contrast_of(material: str, texture: float | None = None) -> float:
    """A surface's texture contrast: its own number, else its material's."""
    return float(texture) if texture is not None else MATERIALS[material]


def lookup_table(contrast_by_id: dict[int, float]) -> np.ndarray:
    """A per-segmentation-id array of texture contrast (ids not listed: 0, no texture)."""
    lut = np.zeros(max(contrast_by_id, default=0) + 1, dtype=np.float32)
    for i, c in contrast_by_id.items():
        lut[i] = c
    return lut
