"""The nominal opening searched for round a coarse estimate (perception/opening_search.py)
and the fine look's check that it shows the opening (perception/view.py): on synthetic
coarse views of a plate, dense and sparse, with a wall, a second opening and none; and the
fine stage's fit reaching as far as the search (`locate_opening`)."""

from __future__ import annotations

import numpy as np
import pytest

from cfvs_maniskill.perception.opening import fit_opening
from cfvs_maniskill.perception.opening_search import RADIUS, locate_opening, search_opening
from cfvs_maniskill.perception.view import points_at_opening

HALF = 0.025  # the 4 mm tasks' square hole and round hole radius


def _inside(xy: np.ndarray, at, round_opening: bool) -> np.ndarray:
    d = xy - np.asarray(at)
    return np.hypot(*d.T) < HALF if round_opening else np.abs(d).max(axis=1) < HALF


def _plate(rng, openings=((0.0, 0.0),), round_opening=False, n=60000, noise=0.0005, wall=None):
    """Points of a 24 cm plate (top at z = 0) with the given openings (the hole's floor
    30 mm down shows through each), seen from above; optionally a wall 8 cm tall standing
    `wall` m beyond the +x side of the first opening."""
    xy = rng.uniform(-0.12, 0.12, size=(n, 2))
    z = np.zeros(n)
    for at in openings:
        z[_inside(xy, at, round_opening)] = -0.03
    pts = [np.column_stack([xy, z])]
    if wall is not None:
        x0 = openings[0][0] + HALF + wall
        top = rng.uniform([x0, -0.1], [x0 + 0.01, 0.1], size=(n // 20, 2))
        pts.append(np.column_stack([top, np.full(len(top), 0.08)]))
        side = rng.uniform([-0.1, 0.0], [0.1, 0.08], size=(n // 10, 2))
        pts.append(np.column_stack([np.full(len(side), x0), side[:, 0], side[:, 1]]))
    p = np.vstack(pts)
    return p + rng.normal(0.0, noise, p.shape)


def _estimate(x: float, y: float, z: float = 0.0) -> np.ndarray:
    H = np.eye(4)
    H[:3, 3] = (x, y, z)
    return H


@pytest.mark.parametrize("round_opening", [False, True])
@pytest.mark.parametrize("wall", [None, 0.02])
def test_the_opening_is_found_from_an_estimate_centimetres_off(round_opening, wall):
    rng = np.random.default_rng(0)
    pts = _plate(rng, round_opening=round_opening, wall=wall)
    # OAKN beside a wall: 15-30 mm off across the face and up to centimetres in height.
    for start in [(0.018, -0.012, 0.04), (-0.025, 0.02, -0.01), (0.0, 0.03, 0.0)]:
        F = search_opening(pts, _estimate(*start), HALF, round_opening)
        assert F is not None, start
        assert np.linalg.norm(F[:2, 3]) < 0.002, (start, F[:3, 3])
        assert abs(F[2, 3]) < 0.001, (start, F[:3, 3])  # onto the face
        assert np.allclose(F[:3, :3], np.eye(3))  # moved, not turned


def test_a_sparse_noisy_cloud_still_gives_the_opening():
    """A passive stereo camera on a plain part: a thousand points, 2 mm noise."""
    rng = np.random.default_rng(1)
    pts = _plate(rng, n=1500, noise=0.002)
    F = search_opening(pts, _estimate(0.012, 0.01, 0.01), HALF)
    assert F is not None and np.linalg.norm(F[:2, 3]) < 0.005, F


def test_no_answer_where_no_opening_stands_out():
    rng = np.random.default_rng(2)
    start = _estimate(0.01, 0.0)
    assert search_opening(_plate(rng, openings=()), start, HALF) is None  # a plain plate
    # Two openings 7 cm apart, the estimate between them: either would do as well.
    twins = _plate(rng, openings=((-0.035, 0.0), (0.035, 0.0)))
    assert search_opening(twins, _estimate(0.0, 0.0), HALF) is None
    # From beside one of them the other is beyond the search: the nearer is taken.
    F = search_opening(twins, _estimate(-0.03, 0.0), HALF)
    assert F is not None and np.linalg.norm(F[:2, 3] - (-0.035, 0.0)) < 0.002
    # An opening beyond the search radius is matched in part at its edge at most: the
    # estimate moves towards it, never away.
    far = _plate(rng, openings=((RADIUS + 0.02, 0.0),))
    F = search_opening(far, _estimate(0.0, 0.0), HALF)
    assert F is None or 0.0 < F[0, 3] <= RADIUS + 0.001
    assert search_opening(np.zeros((0, 3)), start, HALF) is None


def test_a_view_of_a_walls_back_shows_no_points_at_the_opening():
    rng = np.random.default_rng(3)
    plate = _plate(rng, wall=0.02)
    H = _estimate(0.0, 0.0)
    assert points_at_opening(plate, H, HALF) > 1000
    wall_only = plate[plate[:, 0] > HALF + 0.015]  # what the camera behind the wall sees
    assert points_at_opening(wall_only, H, HALF) == 0
    # Round: the corners of the square round the circle are not counted.
    corner = np.array([[HALF + 0.008, HALF + 0.008, 0.0]])
    assert points_at_opening(corner, H, HALF) == 1
    assert points_at_opening(corner, H, HALF, round_opening=True) == 0


@pytest.mark.parametrize("round_opening", [False, True])
def test_an_opening_beyond_the_fits_reach_is_searched_for_then_fitted(round_opening):
    """OPN's estimate 15-25 mm off: beyond the few millimetres the fit looks over, within
    the search's radius; the opening is fitted where the search puts it, to the fit's
    precision, and near the estimate the fit alone answers."""
    rng = np.random.default_rng(4)
    pts = _plate(rng, round_opening=round_opening, wall=0.02, noise=0.0003)
    for start in [(0.015, -0.01), (-0.02, 0.012), (0.0, 0.025)]:
        off = _estimate(*start)
        assert fit_opening(pts, off, HALF, round_opening) is None, start
        F = locate_opening(pts, off, HALF, round_opening)
        assert F is not None and np.linalg.norm(F[:2, 3]) < 0.0007, (start, F)
        assert abs(F[2, 3]) < 0.001, (start, F[:3, 3])
    near = _estimate(0.002, -0.001)
    F = locate_opening(pts, near, HALF, round_opening)
    assert np.allclose(F, fit_opening(pts, near, HALF, round_opening))
    assert locate_opening(_plate(rng, openings=()), near, HALF, round_opening) is None
