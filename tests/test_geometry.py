"""SE(3) helpers: the fast matrix-to-quaternion conversion gives SciPy's bits."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cfvs_maniskill import geometry as G


def _scipy_wxyz(R: np.ndarray) -> np.ndarray:
    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return np.array([w, x, y, z])


def test_quaternion_is_scipys_to_the_last_bit():
    """Orthogonal matrices (every branch of the largest component, half turns, tiny
    angles) and float32 poses (not orthogonal to 1e-12: the SVD branch) give exactly
    SciPy's float64 quaternion, so SAPIEN's pose and every episode stay the same."""
    g = np.random.default_rng(0)
    mats = list(Rotation.random(3000, random_state=1).as_matrix())
    mats += [np.eye(3), np.diag([1.0, -1, -1]), np.diag([-1.0, 1, -1]), np.diag([-1.0, -1, 1])]
    mats += [Rotation.from_rotvec(v).as_matrix() for v in g.normal(size=(500, 3)) * 1e-4]
    half = g.normal(size=(500, 3))
    half *= (np.pi - 1e-6) / np.linalg.norm(half, axis=1, keepdims=True)
    mats += list(Rotation.from_rotvec(half).as_matrix())
    f32 = Rotation.random(2000, random_state=2).as_matrix().astype(np.float32)
    mats += list(f32.astype(np.float64))
    branches = set()
    for R in mats:
        assert np.array_equal(np.array(G.quaternion(R)), _scipy_wxyz(R)), R
        branches.add(int(np.argmax([R[0, 0], R[1, 1], R[2, 2], np.trace(R)])))
    assert branches == {0, 1, 2, 3}
    T = G.make(mats[-1], np.array([0.1, -0.2, 0.3]))
    pose = G.to_pose(T)
    assert np.allclose(pose.to_transformation_matrix(), T, atol=1e-6)


def test_quaternion_refuses_a_reflection():
    for reflection in (np.diag([1.0, 1.0, -1.0]), np.diag([1.0, 1.0, -1.0]) * 1.001):
        with pytest.raises(ValueError, match="determinant"):
            G.quaternion(reflection)
