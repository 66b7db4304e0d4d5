"""A sensor profile in action for one env: draws the per-episode errors (hand-eye, wrench
bias, depth scale and offset, intrinsics, the depth noise's fixed pattern) from the
episode's seed and corrupts each observation with its own generator.

Every random draw is a function of (episode seed, what is drawn, which observation or
control step), so a restored state reproduces the same sensor readings without replaying
anything."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from cfvs_maniskill import geometry as G
from cfvs_maniskill.sensing.depth import EpisodeDepth, apply_stereo
from cfvs_maniskill.sensing.profile import DepthModel, SensorProfile

GL_TO_CV = np.diag([1.0, -1.0, -1.0, 1.0])
"""OpenGL camera axes (x right, y up, z back) <-> OpenCV's (x right, y down, z forward)."""
SAPIEN_CAM_TO_GL = np.array(
    [[0.0, 0.0, -1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)
"""The OpenGL camera axes in a SAPIEN camera's frame (x forward, y left, z up)."""

_HAND_EYE, _WRENCH_BIAS, _WRENCH_NOISE, _DEPTH, _DEPTH_BIAS, _FIXED = 1, 2, 3, 4, 5, 6
"""Stream tags: each kind of draw has its own generator."""


def mount_errors(
    translation: float, rotation_deg: float, rng: np.random.Generator, n: int
) -> np.ndarray:
    """(n, 4, 4) rigid transforms, each moving by exactly `translation` m and turning by
    exactly `rotation_deg`, in uniformly random directions (per transform: the turn's
    direction, then the move's, three normal draws each)."""
    v = rng.standard_normal((n, 2, 3))
    v /= np.linalg.norm(v, axis=2, keepdims=True)
    M = np.tile(np.eye(4), (n, 1, 1))
    M[:, :3, :3] = Rotation.from_rotvec(np.radians(rotation_deg) * v[:, 0]).as_matrix()
    M[:, :3, 3] = translation * v[:, 1]
    return M


def depth_errors(d: DepthModel, u: np.ndarray) -> dict[str, np.ndarray]:
    """The depth camera's calibration errors for uniform draws `u` (..., 5) in [-1, 1]:
    scale, offset, true / reported focal ratio and the principal-point offset (..., 2),
    each within the profile's bound."""
    return dict(
        scale=1.0 + d.depth_scale_error * u[..., 0],
        offset=d.depth_offset_error * u[..., 1],
        focal_ratio=1.0 / (1.0 + d.focal_error * u[..., 2]),
        principal=d.principal_point_error_px * u[..., 3:5],
    )


def mount_error(translation: float, rotation_deg: float, rng: np.random.Generator) -> np.ndarray:
    """One of `mount_errors`: a rigid 4x4 transform moving by exactly `translation` m and
    turning by exactly `rotation_deg`, in random directions."""
    return mount_errors(translation, rotation_deg, rng, 1)[0]


class SensorModel:
    def __init__(self, profile: SensorProfile, iid_std: float):
        self.profile = profile
        self.iid_std = iid_std
        """Per-point noise of an iid depth model, m (profile's std, else the task's)."""
        self.seed = 0
        self.mount = np.eye(4)
        """The camera's true mount relative to the nominal one (SAPIEN camera frame)."""
        self.wrench_bias = np.zeros(6)
        self.depth_errors = EpisodeDepth()
        """The depth camera's errors for this episode (scale, offset, intrinsics, fixed
        pattern)."""

    @property
    def is_iid(self) -> bool:
        return self.profile.depth.model == "iid"

    def start_episode(self, seed: int) -> None:
        self.seed = int(seed)
        he, w = self.profile.hand_eye, self.profile.wrench
        self.mount = np.eye(4)
        if he.translation > 0 or he.rotation_deg > 0:
            rng = np.random.default_rng([self.seed, _HAND_EYE])
            self.mount = mount_error(he.translation, he.rotation_deg, rng)
        scale = np.array([w.force_bias] * 3 + [w.torque_bias] * 3)
        self.wrench_bias = np.random.default_rng([self.seed, _WRENCH_BIAS]).standard_normal(6)
        self.wrench_bias *= scale
        self.depth_errors = self._draw_depth_errors()

    def _draw_depth_errors(self) -> EpisodeDepth:
        """Scale, offset and intrinsics errors, uniform within the profile's bounds; the
        fixed-pattern fields are drawn when the image size is first seen."""
        u = np.random.default_rng([self.seed, _DEPTH_BIAS]).uniform(-1.0, 1.0, 5)
        e = depth_errors(self.profile.depth, u)
        return EpisodeDepth(
            scale=float(e["scale"]),
            offset=float(e["offset"]),
            focal_ratio=float(e["focal_ratio"]),
            principal_offset=(float(e["principal"][0]), float(e["principal"][1])),
        )

    def _fixed_fields(self, shape: tuple[int, int]) -> EpisodeDepth:
        """The episode's errors with fixed-pattern fields of this image size."""
        e = self.depth_errors
        if e.fixed_noise is None or e.fixed_noise.shape != shape:
            rng = np.random.default_rng([self.seed, _FIXED, *shape])
            e.fixed_noise = rng.standard_normal(shape, dtype=np.float32)
            e.fixed_uniform = rng.random(shape, dtype=np.float32)
        return e

    def wrench_error(self, step: int) -> np.ndarray:
        """Bias + noise of the wrench reading at control step `step` (one sample per step)."""
        w = self.profile.wrench
        if w.force_noise == 0 and w.torque_noise == 0:
            return self.wrench_bias.copy()
        rng = np.random.default_rng([self.seed, _WRENCH_NOISE, step])
        scale = np.array([w.force_noise] * 3 + [w.torque_noise] * 3)
        return self.wrench_bias + rng.standard_normal(6) * scale

    def reported_cam2world_gl(self, true_cam2world_gl: np.ndarray) -> np.ndarray:
        """Where the robot believes the camera is (the nominal mount) given where it really
        is: the true pose with the mount error taken back out."""
        g = SAPIEN_CAM_TO_GL
        return true_cam2world_gl @ G.inv(g) @ G.inv(self.mount) @ g

    def reported_intrinsic(self, true_intrinsic: np.ndarray) -> np.ndarray:
        """The rendered image's 3x3 camera matrix as the robot believes it: the episode's
        focal and principal-point errors (sensor pixels, scaled to the render's)."""
        e = self.depth_errors
        K = np.array(true_intrinsic, dtype=np.float64)
        if not e.intrinsics_off:
            return K
        to_render = K[0, 0] / self.profile.depth.focal_px
        K[0, 0] /= e.focal_ratio
        K[1, 1] /= e.focal_ratio
        K[0, 2] -= e.principal_offset[0] * to_render
        K[1, 2] -= e.principal_offset[1] * to_render
        return K

    def depth_rng(self, draw: int) -> np.random.Generator:
        return np.random.default_rng([self.seed, _DEPTH, draw])

    def stereo_points_cv(
        self,
        points: np.ndarray,
        valid: np.ndarray,
        draw: int,
        intrinsic: np.ndarray,
        surface: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """(H, W, 3) OpenCV camera-frame points -> the stereo sensor's (observation `draw`;
        `intrinsic`: the rendered image's 3x3 camera matrix; `surface`: per-pixel albedo
        and texture contrast)."""
        pixel_angle = 1.0 / float(intrinsic[0, 0])
        episode = self._fixed_fields(points.shape[:2])
        return apply_stereo(
            points, valid, self.profile.depth, self.depth_rng(draw), pixel_angle, surface, episode
        )

    def stereo_points_gl(
        self,
        points_gl: np.ndarray,
        valid: np.ndarray,
        draw: int,
        intrinsic: np.ndarray,
        surface: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """As stereo_points_cv, in OpenGL camera axes."""
        flip = np.array([1.0, -1.0, -1.0], dtype=np.float32)
        out, ok = self.stereo_points_cv(points_gl * flip, valid, draw, intrinsic, surface)
        return out * flip, ok
