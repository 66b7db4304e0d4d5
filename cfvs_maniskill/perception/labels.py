"""Ground-truth labels from true poses: OAKN's keypoints, offsets and confidence, OPN's actions.

All labels are in the tool frame at capture time (see `clouds.py`).

Keypoints (paper, OAKN): k1 the hole's centre on its top face, k2 = k1 + s * x_hole,
k3 = k1 + s * z_hole (z out of the hole), s = `KEYPOINT_SPACING`. A square hole has four
equally valid x axes and a round one infinitely many; a label must be a function of what
the camera sees, so x_hole is the one closest to the tool's own x axis -- the axis the
executor would turn the peg to anyway (`PegInsertEnv.insertion_pose`).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from cfvs_maniskill import geometry as G
from cfvs_maniskill.constants import PRE_INSERT_HEIGHT

KEYPOINT_SPACING = 0.05
"""Distance of k2 and k3 from k1, metres."""
CONFIDENCE_SIGMA = 0.03
"""sigma of the confidence target w* = exp(-|x - p|^2 / 2 sigma^2), metres."""


def canonical_hole_frame(hole: np.ndarray, tcp: np.ndarray, peg: str) -> np.ndarray:
    """The hole's world pose with its x axis the symmetric choice nearest the tool's x."""
    z = hole[:3, 2]
    x_tool = tcp[:3, 0]
    if peg == "square":
        cands = [hole[:3, 0], hole[:3, 1], -hole[:3, 0], -hole[:3, 1]]
        x = max(cands, key=lambda c: float(c @ x_tool))
    else:
        x = x_tool
    return G.make(G.frame_with_z(z, x), hole[:3, 3])


def keypoints_world(hole: np.ndarray, tcp: np.ndarray, peg: str) -> np.ndarray:
    """(3, 3) rows k1, k2, k3 in the world frame."""
    H = canonical_hole_frame(hole, tcp, peg)
    k1 = H[:3, 3]
    return np.stack([k1, k1 + KEYPOINT_SPACING * H[:3, 0], k1 + KEYPOINT_SPACING * H[:3, 2]])


def offsets(points: np.ndarray, keypoints: np.ndarray) -> np.ndarray:
    """(N, 3, 3): offsets[i, j] = k_j - x_i, so x_i + offsets[i, j] = k_j exactly."""
    return (keypoints[None, :, :] - points[:, None, :]).astype(np.float32)


def confidence(points: np.ndarray, centre: np.ndarray, sigma: float = CONFIDENCE_SIGMA):
    """(N,) w* = exp(-|x - p|^2 / 2 sigma^2) around the hole's centre p."""
    d2 = np.sum((points - centre) ** 2, axis=-1)
    return np.exp(-d2 / (2 * sigma**2)).astype(np.float32)


def hole_frame_from_keypoints(k: np.ndarray) -> np.ndarray:
    """The paper's Algorithm 1 (compute_rot_mat) plus the position: 4x4 hole frame."""
    vx, vz = k[1] - k[0], k[2] - k[0]
    vz = vz / np.linalg.norm(vz)
    vy = np.cross(vz, vx)
    vy = vy / np.linalg.norm(vy)
    vx = np.cross(vy, vz)
    return G.make(np.stack([vx, vy, vz], axis=1), k[0])


def fine_action(tcp: np.ndarray, target: np.ndarray) -> np.ndarray:
    """OPN's label: (dt, dr) such that target = tcp @ [rotvec(dr) | dt] (tool frame).

    The paper writes Algorithm 2 as R' = dR R, t' = dt + t in the world; the network sees
    a tool-frame cloud, so we express the same offset in the tool frame, where it is a
    function of the observation. dr is a rotation vector (radians), not Euler angles: for
    the small offsets here they agree to first order and it has no gimbal order to choose.
    """
    D = G.inv(tcp) @ target
    dr = Rotation.from_matrix(D[:3, :3]).as_rotvec()
    return np.concatenate([D[:3, 3], dr]).astype(np.float32)


def apply_action(tcp: np.ndarray, action: np.ndarray) -> np.ndarray:
    """The inverse of `fine_action`: the pose OPN's (dt, dr) asks for."""
    D = G.make(Rotation.from_rotvec(action[3:6]).as_matrix(), action[:3])
    return tcp @ D


def random_offset(
    rng: np.random.Generator, max_translation: float, max_tilt_deg: float, max_yaw_deg: float
) -> np.ndarray:
    """A random 4x4 tool-frame offset: translation of uniform length in any direction,
    rotation about the tool axis (yaw) and about an axis across it (tilt), uniform angles.
    Uniform lengths (not uniform in the ball) keep many small offsets, which the last fine
    iterations need most."""
    d = rng.normal(size=3)
    t = d / np.linalg.norm(d) * rng.uniform(0, max_translation)
    phi = rng.uniform(0, 2 * np.pi)
    tilt = np.radians(rng.uniform(0, max_tilt_deg)) * np.array([np.cos(phi), np.sin(phi), 0.0])
    yaw = np.radians(rng.uniform(-max_yaw_deg, max_yaw_deg))
    R = Rotation.from_rotvec(tilt).as_matrix() @ Rotation.from_rotvec([0, 0, yaw]).as_matrix()
    return G.make(R, t)


def encode_symmetric_x(k: np.ndarray, symmetry: int = 4) -> np.ndarray:
    """Keypoints (3, 3) in the tool frame with k2 re-encoded so that it is continuous in
    the hole's yaw despite the hole's symmetry (`symmetry`-fold; 4 for a square).

    With u the tool's x projected on the hole's plane and theta the angle from u to the
    hole's canonical x (|theta| <= 45 deg), k2 = k1 + s (cos(4 theta) u + sin(4 theta) z x u):
    a square turned by 90 deg gets the same label, so nothing jumps at theta = +-45 deg. A
    round hole has theta = 0, so k2 is simply along u.
    """
    k1, k2, k3 = (np.asarray(v, np.float64) for v in k)
    z = (k3 - k1) / np.linalg.norm(k3 - k1)
    u = _projected_tool_x(z)
    x = k2 - k1
    theta = np.arctan2(x @ np.cross(z, u), x @ u)
    phi = symmetry * theta
    v = np.cos(phi) * u + np.sin(phi) * np.cross(z, u)
    return np.stack([k1, k1 + KEYPOINT_SPACING * v, k3]).astype(np.float32)


def decode_symmetric_x(k: np.ndarray, symmetry: int = 4) -> np.ndarray:
    """Inverse of `encode_symmetric_x`: the 4x4 hole frame (tool frame) from keypoints."""
    k1, k2, k3 = (np.asarray(v, np.float64) for v in k)
    z = (k3 - k1) / np.linalg.norm(k3 - k1)
    u = _projected_tool_x(z)
    v = k2 - k1
    theta = np.arctan2(v @ np.cross(z, u), v @ u) / symmetry
    x = np.cos(theta) * u + np.sin(theta) * np.cross(z, u)
    return G.make(np.stack([x, np.cross(z, x), z], axis=1), k1)


def _projected_tool_x(z: np.ndarray) -> np.ndarray:
    u = np.array([1.0, 0.0, 0.0]) - z[0] * z
    return u / np.linalg.norm(u)


def fine_keypoints(action: np.ndarray) -> np.ndarray:
    """A fine sample's keypoints (tool frame) from its action: the target pre-insertion
    tool frame is PRE_INSERT_HEIGHT above the hole's centre, its z into the hole, its x the
    hole's canonical x."""
    H = hole_frame_from_pre_insertion(apply_action(np.eye(4), np.asarray(action, np.float64)))
    c, s = H[:3, 3], KEYPOINT_SPACING
    return np.stack([c, c + s * H[:3, 0], c + s * H[:3, 2]])


def fine_action_from_keypoints(k: np.ndarray) -> np.ndarray:
    """Voted fine keypoints (tool frame, k2 symmetry-encoded) -> the offset (dt, dr) to the
    pre-insertion pose above the hole, facing into it. Inverse of `fine_keypoints` +
    `encode_symmetric_x`."""
    H = decode_symmetric_x(k)
    R = H[:3, :3] @ np.diag([1.0, -1.0, -1.0])  # tool z into the hole, tool x = hole x
    return fine_action(np.eye(4), G.make(R, H[:3, 3] + PRE_INSERT_HEIGHT * H[:3, 2]))


def hole_frame_from_pre_insertion(T: np.ndarray) -> np.ndarray:
    """The hole frame (origin at the opening, z out of the hole) that the pre-insertion tcp
    pose T (4x4, tool z into the hole, x the hole's x) stands PRE_INSERT_HEIGHT above."""
    H = np.eye(4)
    H[:3, :3] = T[:3, :3] @ np.diag([1.0, -1.0, -1.0])
    H[:3, 3] = T[:3, 3] + PRE_INSERT_HEIGHT * T[:3, 2]
    return H
