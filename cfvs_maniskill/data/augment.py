"""The paper's data augmentation: random scaling and random rotation of the object along its
x and y axes, or both, with the points near the hole kept undeformed.

It acts on one tool-frame cloud and the sample's keypoints (which define the hole frame);
the hole, and so every label that depends on it, is unchanged, and callers recompute the
per-point offsets / confidence from the new points. Cheap enough (numpy, ~0.1 ms for 1024
points) to run on the fly in a training DataLoader, so every epoch sees new shapes.

Scaling stretches the body away from the hole: along each axis, a point |u| > r0 from the
hole's centre moves to r0 + s (|u| - r0), a continuous map that is the identity within r0.
Rotation bends the body about the hole frame's x / y axes through the hole's centre, by an
angle that ramps from 0 at r0 to the full angle `ramp` further out, so surfaces stay
connected and the hole itself does not move.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from cfvs_maniskill.perception.labels import hole_frame_from_keypoints


@dataclass(frozen=True)
class AugmentConfig:
    p_scale: float = 0.25
    """Probability of scaling only (paper: (a) random scaling)."""
    p_rotate: float = 0.25
    """Probability of rotation only (paper: (b) random rotation)."""
    p_mix: float = 0.25
    """Probability of both (paper: (c) mix); otherwise the sample is left as it is."""
    scale: tuple[float, float] = (0.7, 1.4)
    """Range of the scale factor per axis, applied beyond `keep_radius`."""
    max_angle_deg: float = 20.0
    """Largest bend about the hole's x and y axes."""
    keep_radius: float = 0.04
    """Points this close (m, across the hole axis) to the hole's centre are never moved."""
    ramp: float = 0.03
    """The bend reaches its full angle this far (m) beyond `keep_radius`."""


def scale_away_from_hole(u: np.ndarray, sx: float, sy: float, r0: float) -> np.ndarray:
    """Hole-frame points u (N, 3): stretch x by sx and y by sy beyond r0 from the centre."""
    out = u.copy()
    for axis, s in ((0, sx), (1, sy)):
        a = np.abs(u[:, axis])
        far = a > r0
        out[far, axis] = np.sign(u[far, axis]) * (r0 + s * (a[far] - r0))
    return out


def bend_away_from_hole(u: np.ndarray, ax: float, ay: float, r0: float, ramp: float):
    """Rotate hole-frame points about x by ax and y by ay (radians), ramped in from r0."""
    r = np.hypot(u[:, 0], u[:, 1])
    w = np.clip((r - r0) / ramp, 0.0, 1.0)
    rotvec = w[:, None] * np.array([ax, ay, 0.0])[None]
    return Rotation.from_rotvec(rotvec).apply(u)


def augment(
    points: np.ndarray, keypoints: np.ndarray, rng: np.random.Generator, cfg: AugmentConfig
) -> tuple[np.ndarray, str]:
    """Augmented copy of `points` (N, 3, tool frame) and which augmentation was applied."""
    roll = rng.uniform()
    if roll < cfg.p_scale:
        kind = "scale"
    elif roll < cfg.p_scale + cfg.p_rotate:
        kind = "rotate"
    elif roll < cfg.p_scale + cfg.p_rotate + cfg.p_mix:
        kind = "mix"
    else:
        return points, "none"
    H = hole_frame_from_keypoints(np.asarray(keypoints, np.float64))
    R, c = H[:3, :3], H[:3, 3]
    u = (points - c) @ R
    if kind in ("scale", "mix"):
        sx, sy = rng.uniform(*cfg.scale, size=2)
        u = scale_away_from_hole(u, sx, sy, cfg.keep_radius)
    if kind in ("rotate", "mix"):
        ax, ay = np.radians(rng.uniform(-cfg.max_angle_deg, cfg.max_angle_deg, size=2))
        u = bend_away_from_hole(u, ax, ay, cfg.keep_radius, cfg.ramp)
    return (u @ R.T + c).astype(np.float32), kind
