"""A stereo depth camera's errors, applied to a rendered (exact) depth image.

Works on camera-frame points on the image grid (OpenCV convention: z forward, metres), so
the same model serves the wrist point cloud and the wrist depth image. In order:

1. grazing incidence: no return where the surface is seen more obliquely than
   `max_incidence_deg`;
2. occlusion: no return where the right imager cannot see the point (one-sided, along the
   baseline);
3. texture: the matcher needs image texture. Each pixel's signal (albedo x the surface's
   texture contrast x cos incidence, with a projector's pattern added in quadrature) against
   the imagers' noise sets its disparity noise and whether it matches at all
   (results/texture_study, measured with OpenCV's SGBM);
4. depth discontinuities (a neighbour more than `edge_jump` nearer or further, or with no
   return): the pixel is dropped (failed left-right check) or becomes a "flying pixel"
   between the near and far side (the matching window straddles the edge);
5. the episode's depth scale and offset error, then axial noise in disparity d = f B / z
   (Gaussian, `disparity_noise_px`; a `fixed_pattern` share of it fixed for the episode),
   so depth noise grows as z^2 (Intel's RMS error = z^2 * subpixel / (f * B)), then the
   disparity's and the depth unit's quantisation;
6. lateral jitter of each pixel's ray and the episode's intrinsics error (the cloud is
   formed with the reported intrinsics); 7. range limits.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr

from cfvs_maniskill.sensing.profile import DepthModel

_NEIGHBOURS = ((0, 1), (0, -1), (1, 0), (-1, 0))


def _shifted(a: np.ndarray, dy: int, dx: int, fill) -> np.ndarray:
    """a shifted by (dy, dx) pixels; what comes in from outside the image is `fill`."""
    out = np.full_like(a, fill)
    h, w = a.shape[:2]
    ys, yd = (slice(0, h - dy), slice(dy, h)) if dy >= 0 else (slice(-dy, h), slice(0, h + dy))
    xs, xd = (slice(0, w - dx), slice(dx, w)) if dx >= 0 else (slice(-dx, w), slice(0, w + dx))
    out[yd, xd] = a[ys, xs]
    return out


def _smooth_side(p: np.ndarray, dy: int, dx: int) -> np.ndarray:
    """The tangent along one image axis, from the neighbour on the side where depth changes
    least: at a depth discontinuity that is the pixel's own surface, not the jump."""
    fwd = _shifted(p, -dy, -dx, np.nan) - p
    bwd = p - _shifted(p, dy, dx, np.nan)
    with np.errstate(invalid="ignore"):
        use_fwd = np.isnan(bwd[..., 2]) | (np.abs(fwd[..., 2]) < np.abs(bwd[..., 2]))
    return np.where(use_fwd[..., None], fwd, bwd)


def incidence_deg(points: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Angle between each pixel's ray and its surface normal (from the neighbouring pixels'
    points), degrees; NaN where the neighbours needed are missing."""
    p = np.where(valid[..., None], points, np.float32(np.nan))
    du, dv = _smooth_side(p, 0, 1), _smooth_side(p, 1, 0)
    n = np.empty_like(du)  # du x dv, written out (np.cross is slower on small arrays)
    n[..., 0] = du[..., 1] * dv[..., 2] - du[..., 2] * dv[..., 1]
    n[..., 1] = du[..., 2] * dv[..., 0] - du[..., 0] * dv[..., 2]
    n[..., 2] = du[..., 0] * dv[..., 1] - du[..., 1] * dv[..., 0]
    dot = np.abs(np.einsum("hwc,hwc->hw", n, points))
    norm = np.sqrt(np.einsum("hwc,hwc->hw", n, n) * np.einsum("hwc,hwc->hw", points, points))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.degrees(np.arccos(np.minimum(dot / norm, 1.0)))


def edge_mask(z: np.ndarray, valid: np.ndarray, jump) -> np.ndarray:
    """Valid pixels next to a depth jump larger than `jump` (m, a scalar or per pixel) or
    to a pixel with no return."""
    edge = np.zeros_like(valid)
    for dy, dx in _NEIGHBOURS:
        zn = _shifted(z, dy, dx, np.nan)
        vn = _shifted(valid, dy, dx, True)  # the image border is not an edge
        with np.errstate(invalid="ignore"):
            edge |= ~vn | (np.abs(zn - z) > jump)
    return edge & valid


def neighbour_range(z: np.ndarray, valid: np.ndarray, rows, cols) -> tuple[np.ndarray, np.ndarray]:
    """Nearest and furthest valid depth in the 3 x 3 neighbourhoods of pixels (rows, cols)."""
    zp = np.pad(np.where(valid, z, np.nan), 1, constant_values=np.nan)
    block = np.stack([zp[rows + dy, cols + dx] for dy in range(3) for dx in range(3)])
    return np.nanmin(block, axis=0), np.nanmax(block, axis=0)


def discontinuity_jump(z: np.ndarray, model: DepthModel, pixel_angle: float) -> np.ndarray:
    """The depth step between neighbouring pixels (m) that no returned surface makes: a
    surface tilted by the largest incidence the sensor still returns steps by
    z * tan(incidence) * pixel_angle; half again more than that (or `edge_jump`, if larger)
    is a discontinuity, not an oblique surface."""
    steepest = np.tan(np.radians(min(model.max_incidence_deg, 85.0)))
    return np.maximum(model.edge_jump, 1.5 * z * steepest * pixel_angle)


@dataclass
class EpisodeDepth:
    """The depth camera's errors fixed for one episode (drawn by `SensorModel`)."""

    scale: float = 1.0
    """Reported / true depth."""
    offset: float = 0.0
    """Added to every depth, m."""
    focal_ratio: float = 1.0
    """True / reported focal length."""
    principal_offset: tuple[float, float] = (0.0, 0.0)
    """(true - reported) principal point, sensor pixels."""
    fixed_noise: np.ndarray | None = None
    """(H, W) standard normal draws: the disparity noise's fixed part."""
    fixed_uniform: np.ndarray | None = None
    """(H, W) uniform draws deciding which pixels of low texture fail to match."""

    @property
    def intrinsics_off(self) -> bool:
        return self.focal_ratio != 1.0 or self.principal_offset != (0.0, 0.0)


def occluded(z: np.ndarray, valid: np.ndarray, focal_render: float, baseline: float):
    """Pixels the right imager (`baseline` m along the image's +x) cannot see: a nearer
    point further right on the row lands at or left of the same right-image column. The
    band falls on one side of every near edge, f B (1/z_near - 1/z_far) wide."""
    cols = np.arange(z.shape[1], dtype=np.float32)[None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        x_right = np.where(valid, cols - focal_render * baseline / z, np.inf)
    # The smallest right-image column of any pixel strictly to the right on the row.
    suffix = np.minimum.accumulate(x_right[:, ::-1], axis=1)[:, ::-1]
    beyond = np.concatenate([suffix[:, 1:], np.full((z.shape[0], 1), np.inf)], axis=1)
    return valid & (beyond < x_right - 1e-3)


def texture_snr(
    model: DepthModel, albedo: np.ndarray, contrast: np.ndarray, cos_inc: np.ndarray
) -> np.ndarray:
    """Each pixel's texture signal over the imagers' noise: the surface's own texture and
    a projector's pattern (both seen foreshortened by the incidence) add in quadrature."""
    own = albedo * contrast
    projected = albedo * model.projector
    return np.hypot(own, projected) * cos_inc / model.imager_noise


def apply_stereo(
    points: np.ndarray,
    valid: np.ndarray,
    model: DepthModel,
    rng: np.random.Generator,
    pixel_angle: float,
    surface: tuple[np.ndarray, np.ndarray] | None = None,
    episode: EpisodeDepth | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(H, W, 3) camera-frame points (z forward) and their validity -> the sensor's.
    `pixel_angle`: the angle between neighbouring pixels' rays (1 / focal length in the
    rendered image's pixels), rad. `surface`: (albedo, texture contrast) per pixel, used
    when the model has `imager_noise`. `episode`: the errors fixed for the episode."""
    episode = episode or EpisodeDepth()
    points = points.astype(np.float32)
    z = points[..., 2]
    valid = valid & (z > 0)
    out_valid = valid.copy()
    texture = model.imager_noise > 0 and surface is not None
    inc = None
    if model.max_incidence_deg < 90 or texture:
        inc = incidence_deg(points, valid)
    if model.max_incidence_deg < 90:
        with np.errstate(invalid="ignore"):
            out_valid &= ~(inc > model.max_incidence_deg)
    if model.occlusion:
        out_valid &= ~occluded(z, valid, 1.0 / pixel_angle, model.baseline)
    noise_gain = np.float32(1.0)
    if texture:
        cos_inc = np.cos(np.radians(np.nan_to_num(inc, nan=0.0))).astype(np.float32)
        # A surface turned away from the camera (cos < 0) has no fill (NaN): it never matches.
        with np.errstate(divide="ignore", invalid="ignore"):
            snr = texture_snr(model, surface[0], surface[1], cos_inc)
            noise_gain = np.sqrt(1 + (model.texture_noise_snr / snr) ** 2).astype(np.float32)
            fill = ndtr(np.log(snr / model.texture_fill_snr) / model.texture_fill_spread)
        matched = fill > _fixed(episode.fixed_uniform, z.shape, True, rng)
        out_valid &= matched
    z_new = z.copy()
    # Every draw is image-sized, so a pixel's noise does not depend on how many edge pixels
    # other parts of the image have (a restored state then reproduces the same image).
    u = rng.random(z.shape, dtype=np.float32)
    mix = rng.random(z.shape, dtype=np.float32)
    if model.edge_dropout > 0 or model.edge_flying > 0:
        jump = discontinuity_jump(z, model, pixel_angle)
        rows, cols = np.nonzero(edge_mask(z, valid, jump))
        draw = u[rows, cols]
        drop = draw < model.edge_dropout
        fly = ~drop & (draw < model.edge_dropout + model.edge_flying)
        r, c = rows[fly], cols[fly]
        zmin, zmax = neighbour_range(z, valid, r, c)
        z_new[r, c] = zmin + mix[r, c] * (zmax - zmin)
        out_valid[rows[drop], cols[drop]] = False
    z_new = z_new * np.float32(episode.scale) + np.float32(episode.offset)
    fb = np.float32(model.focal_px * model.baseline)
    temporal = rng.standard_normal(z.shape, dtype=np.float32)
    if model.fixed_pattern > 0:
        fixed = _fixed(episode.fixed_noise, z.shape, False, rng)
        share = np.float32(model.fixed_pattern)
        temporal = np.sqrt(share) * fixed + np.sqrt(1 - share) * temporal
    with np.errstate(divide="ignore", invalid="ignore"):
        d = fb / z_new
        d += temporal * np.float32(model.disparity_noise_px) * noise_gain
        if model.disparity_step_px > 0:
            step = np.float32(model.disparity_step_px)
            d = np.round(d / step) * step
        z_new = np.where(d > 0, fb / d, np.float32(0.0))
    if model.depth_unit > 0:
        unit = np.float32(model.depth_unit)
        z_new = np.round(z_new / unit) * unit
    out_valid &= (z_new >= model.min_range) & (z_new <= model.max_range)
    with np.errstate(divide="ignore", invalid="ignore"):
        ray = points[..., :2] / z[..., None]  # x/z, y/z of each pixel's ray
    if model.lateral_noise_px > 0:
        jitter = np.float32(model.lateral_noise_px / model.focal_px)
        ray += rng.standard_normal(ray.shape, dtype=np.float32) * jitter
    if episode.intrinsics_off:
        # The robot forms the ray with the reported intrinsics: x' = (u - c') / f'.
        shift = np.asarray(episode.principal_offset, dtype=np.float32) / model.focal_px
        ray = ray * np.float32(episode.focal_ratio) + shift * np.float32(episode.focal_ratio)
    out = np.concatenate([ray * z_new[..., None], z_new[..., None]], axis=-1)
    out[~out_valid] = 0.0
    return out, out_valid


def _fixed(draws: np.ndarray | None, shape, uniform: bool, rng: np.random.Generator):
    """The episode's fixed draws for an image of `shape`; with none (no episode), fresh
    ones: every observation is then a new episode's."""
    if draws is None:
        return (
            rng.random(shape, dtype=np.float32)
            if uniform
            else rng.standard_normal(shape, dtype=np.float32)
        )
    if draws.shape != tuple(shape):
        raise ValueError(f"fixed-pattern draws are {draws.shape}, the image is {shape}")
    return draws


def grid_points(depth: np.ndarray, intrinsic: np.ndarray) -> np.ndarray:
    """(H, W) depth (m) and the 3x3 OpenCV intrinsics -> (H, W, 3) camera-frame points."""
    h, w = depth.shape
    v, u = np.mgrid[0:h, 0:w].astype(np.float32) + 0.5
    x = (u - intrinsic[0, 2]) / intrinsic[0, 0]
    y = (v - intrinsic[1, 2]) / intrinsic[1, 1]
    return np.stack([x * depth, y * depth, depth], axis=-1).astype(np.float32)
