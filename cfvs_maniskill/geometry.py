"""Small SE(3) helpers on 4x4 numpy matrices (metres, radians), and a robust spread."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

if TYPE_CHECKING:  # SAPIEN only for its Pose type: geometry is used without the simulator
    import sapien


def to_matrix(pose: sapien.Pose) -> np.ndarray:
    return np.asarray(pose.to_transformation_matrix(), dtype=np.float64)


def quaternion(R: np.ndarray) -> tuple[float, float, float, float]:
    """(w, x, y, z) of a rotation matrix, the arithmetic of SciPy's
    `Rotation.from_matrix(R).as_quat()` step for step (a matrix that is not orthogonal to
    1e-12, as any float32 pose is, replaced by its SVD polar factor; the largest of the
    four components from the diagonal, the others from the off-diagonals; normalised) on
    plain floats: the same bits, several times cheaper per call. Every IK target and
    object pose goes through `to_pose`, ~40 times per episode."""
    M = np.asarray(R, dtype=np.float64)
    (a, b, c), (d, e, f), (g, h, i) = M.tolist()
    gram = (
        (a * a + b * b + c * c, a * d + b * e + c * f, a * g + b * h + c * i),
        (d * a + e * b + f * c, d * d + e * e + f * f, d * g + e * h + f * i),
        (g * a + h * b + i * c, g * d + h * e + i * f, g * g + h * h + i * i),
    )
    if a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) <= 0:
        raise ValueError(f"not a rotation (determinant <= 0): {M.tolist()}")  # as SciPy
    # numpy.isclose(gram, eye, atol=1e-12) with its default rtol, as SciPy checks it
    if any(
        abs(gram[r][k] - (r == k)) > 1e-12 + 1e-5 * (r == k) for r in range(3) for k in range(3)
    ):
        U, _, Vt = np.linalg.svd(M, full_matrices=False)
        (a, b, c), (d, e, f), (g, h, i) = (U @ Vt).tolist()
    t = a + e + i
    # numpy.argmax over (a, e, i, t): the first largest
    if a >= e and a >= i and a >= t:
        x, y, z, w = 1 - t + 2 * a, d + b, g + c, h - f
    elif e >= i and e >= t:
        x, y, z, w = b + d, 1 - t + 2 * e, h + f, c - g
    elif i >= t:
        x, y, z, w = c + g, f + h, 1 - t + 2 * i, d - b
    else:
        x, y, z, w = h - f, c - g, d - b, 1 + t
    n = math.sqrt(x * x + y * y + z * z + w * w)
    return w / n, x / n, y / n, z / n


def to_pose(T: np.ndarray) -> sapien.Pose:
    import sapien

    return sapien.Pose(p=T[:3, 3].astype(np.float32), q=quaternion(T[:3, :3]))


def pose_vector(T: np.ndarray) -> np.ndarray:
    """(x, y, z, qw, qx, qy, qz): ManiSkill's raw pose layout."""
    p = to_pose(T)
    return np.concatenate([p.p, p.q])


def make(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p
    return T


def inv(T: np.ndarray) -> np.ndarray:
    R, p = T[:3, :3], T[:3, 3]
    return make(R.T, -R.T @ p)


def rot_angle(R: np.ndarray) -> float:
    """Angle of a rotation matrix, radians."""
    return float(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0)))


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle between two unit vectors, degrees."""
    return float(np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0))))


def shortest_turns(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(..., 3, 3) the smallest rotations taking unit vectors `a` (..., 3) onto `b`."""
    axis = np.cross(a, b)
    sin = np.linalg.norm(axis, axis=-1)
    angle = np.arctan2(sin, np.sum(a * b, axis=-1))
    axis = axis / np.maximum(sin, 1e-12)[..., None]
    return Rotation.from_rotvec(axis * angle[..., None]).as_matrix()


def frame_with_z(z: np.ndarray, x_hint: np.ndarray) -> np.ndarray:
    """Rotation whose z axis is `z` and whose x axis is as close as possible to `x_hint`."""
    z = z / np.linalg.norm(z)
    x = x_hint - (x_hint @ z) * z
    if np.linalg.norm(x) < 1e-6:
        x = np.cross(z, [0.0, 1.0, 0.0]) if abs(z[1]) < 0.9 else np.cross(z, [1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


def random_cone(rng: np.random.Generator, axis: np.ndarray, half_angle: float) -> np.ndarray:
    """A unit vector uniform on the spherical cap of `half_angle` radians around `axis`."""
    cos_t = rng.uniform(np.cos(half_angle), 1.0)
    phi = rng.uniform(0, 2 * np.pi)
    sin_t = np.sqrt(1 - cos_t**2)
    local = np.array([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t])
    return frame_with_z(axis, np.array([1.0, 0, 0])) @ local


def interpolate(T0: np.ndarray, T1: np.ndarray, s: float) -> np.ndarray:
    """Straight line in position, slerp in rotation; s in [0, 1]."""
    return interpolator(T0, T1)(s)


def interpolator(T0: np.ndarray, T1: np.ndarray):
    """`interpolate(T0, T1, s)` as a function of s, with the slerp built once (a move
    interpolates every control step of its path)."""
    slerp = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([T0[:3, :3], T1[:3, :3]])))
    p0, p1 = T0[:3, 3], T1[:3, 3]

    def at(s: float) -> np.ndarray:
        return make(slerp([s]).as_matrix()[0], (1 - s) * p0 + s * p1)

    return at


def robust_sigma(r: np.ndarray, centre: float | None = None) -> float:
    """1.4826 x the median absolute deviation of residuals `r` from `centre` (their median
    if None): the standard deviation of Gaussian inliers, blind to up to half outliers."""
    c = np.median(r) if centre is None else centre
    return 1.4826 * float(np.median(np.abs(r - c)))
