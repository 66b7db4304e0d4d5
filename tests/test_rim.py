"""The hole's axis from the face around the opening (perception/rim.py): the face's normal
through noise and beside a wall, and no answer where the ring holds no face."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from cfvs_maniskill.perception.rim import (
    MAX_TURN_DEG,
    RING_MARGIN,
    RING_WIDTH,
    _hypotheses,
    _least_median,
    _ring,
    align_axis,
    rim_normal,
)

HALF = 0.025 * np.sqrt(2)  # a 50 mm square hole's corner


def _face(rng, normal, n=1500, noise=0.0):
    """Points of a plane through the origin with `normal`, 0-90 mm from the origin, minus
    the opening."""
    R = Rotation.align_vectors([normal], [[0.0, 0.0, 1.0]])[0].as_matrix()
    xy = rng.uniform(-0.09, 0.09, size=(n, 2))
    xy = xy[np.max(np.abs(xy), axis=1) > 0.026]
    p = (
        np.column_stack([xy, rng.normal(0, noise, len(xy))])
        if noise
        else np.column_stack([xy, np.zeros(len(xy))])
    )
    return p @ R.T


def _angle(a, b):
    return np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)))


def test_the_normal_of_a_noisy_face_beside_a_wall_despite_a_wrong_guess():
    rng = np.random.default_rng(0)
    normal = np.array([0.2, -0.1, 1.0]) / np.linalg.norm([0.2, -0.1, 1.0])
    face = _face(rng, normal, noise=0.002)  # 2 mm depth noise
    # A wall 45 mm from the centre, rising 40 mm (a stepped block's step), inside the ring.
    wall = np.column_stack(
        [np.full(300, 0.045), rng.uniform(-0.06, 0.06, 300), rng.uniform(0, 0.04, 300)]
    )
    guess = np.array([0.0, 0.0, 1.0])  # 12.6 deg off, as a fine network beside a step
    n = rim_normal(np.vstack([face, wall]), np.zeros(3), guess, HALF, rng)
    assert n is not None and _angle(n, normal) < 0.5
    assert n @ guess > 0  # on the guess's side


def test_no_answer_without_enough_face_or_for_a_surface_far_from_the_guess():
    rng = np.random.default_rng(1)
    assert rim_normal(_face(rng, np.array([0, 0, 1.0]), n=40), np.zeros(3),
                      np.array([0, 0, 1.0]), HALF, rng) is None  # fmt: skip
    tilted = np.array([np.sin(np.radians(35)), 0, np.cos(np.radians(35))])
    assert MAX_TURN_DEG < 35
    assert rim_normal(_face(rng, tilted), np.zeros(3), np.array([0, 0, 1.0]), HALF, rng) is None


def test_align_axis_turns_z_onto_the_normal_and_keeps_the_origin():
    H = np.eye(4)
    H[:3, 3] = [0.1, 0.2, 0.3]
    normal = np.array([0.1, 0.2, 1.0]) / np.linalg.norm([0.1, 0.2, 1.0])
    out = align_axis(H, normal)
    assert np.allclose(out[:3, 2], normal) and np.allclose(out[:3, 3], H[:3, 3])
    assert np.allclose(out[:3, :3] @ out[:3, :3].T, np.eye(3))
    assert _angle(out[:3, 0], H[:3, 0]) < _angle(normal, H[:3, 2]) + 1e-6  # smallest turn


def test_the_pruned_least_median_picks_what_every_median_picks_bit_for_bit():
    """The fit skips the medians of planes that cannot win; its choice, median and
    distances must be exactly those of the plain rule (argmin of every plane's median),
    also on float64 clouds, quantised clouds (ties) and even point counts."""
    rng = np.random.default_rng(3)
    for trial in range(60):
        n = int(rng.integers(60, 2500))
        pts = np.column_stack([rng.uniform(-0.05, 0.05, (n, 2)), np.zeros(n)])
        pts[:, 2] += rng.normal(0, [0.0, 1e-5, 1e-3, 3e-3][trial % 4], n)
        pts[: int(rng.uniform(0, 0.45) * n), 2] += 0.006  # a step holding up to 45%
        if trial % 5 == 0:
            pts = np.round(pts, 3)  # millimetre steps: many equal distances
        R = Rotation.random(random_state=trial).as_matrix()
        ring = (pts @ R.T + rng.uniform(-0.6, 0.6, 3)).astype(
            np.float64 if trial % 3 == 0 else np.float32
        )
        origins, normals = _hypotheses(ring, rng)
        every = ((ring[None] - origins[:, None]) @ normals[..., None])[..., 0]
        med = np.median(every**2, axis=1)
        best, med_best, residual = _least_median(ring, origins, normals)
        assert best == int(np.argmin(med)), trial
        assert med_best == med[best] and np.array_equal(residual, every[best]), trial


def test_a_square_openings_ring_follows_its_sides_and_falls_back_beyond_its_corners():
    rng = np.random.default_rng(5)
    z = np.array([0.0, 0.0, 1.0])
    plane = np.column_stack([rng.uniform(-0.08, 0.08, (20000, 2)), np.zeros(20000)])
    half = 0.025  # a 50 mm square opening along x and y
    ring = _ring(plane, np.zeros(3), z, half + RING_MARGIN, square_x=np.array([1.0, 0.0, 0.0]))
    cheb = np.max(np.abs(ring[:, :2]), axis=1)
    assert cheb.min() > half + RING_MARGIN and cheb.max() < half + RING_MARGIN + RING_WIDTH
    # Next to a side, where a round ring beyond the corners (39 mm) never looks.
    assert np.any(np.hypot(ring[:, 0], ring[:, 1]) < half * np.sqrt(2))
    # Only the face beyond the square ring in view (as when the peg hides the rest):
    # the round ring beyond the corners still finds it.
    far = plane[(np.max(np.abs(plane[:, :2]), axis=1) > 0.05) & (np.hypot(*plane[:, :2].T) < 0.07)]
    far[:, 2] = rng.normal(0, 0.0005, len(far))
    guess = np.array([np.sin(np.radians(6)), 0.0, np.cos(np.radians(6))])
    n = rim_normal(far, np.zeros(3), guess, half, rng, square_x=np.array([1.0, 0.0, 0.0]))
    assert n is not None and np.degrees(np.arccos(n @ z)) < 1.0


def test_the_face_is_found_when_the_opening_is_estimated_2_cm_too_low():
    """The top of a 5 cm-radius pipe around a 50 mm square opening, with the opening's
    estimate 18 mm below it (as OPN put it on a flanged pipe): the ring's band reaches it."""
    rng = np.random.default_rng(7)
    xy = rng.uniform(-0.05, 0.05, (8000, 2))
    xy = xy[(np.hypot(*xy.T) < 0.05) & (np.max(np.abs(xy), axis=1) > 0.026)]
    top = np.column_stack([xy, rng.normal(0.018, 0.0005, len(xy))])
    a = rng.uniform(0, 2 * np.pi, 1500)
    side = np.column_stack([0.05 * np.cos(a), 0.05 * np.sin(a), rng.uniform(-0.07, 0.018, 1500)])
    n = rim_normal(
        np.vstack([top, side]),
        np.zeros(3),
        np.array([0.0, 0.0, 1.0]),
        0.025,
        rng,
        square_x=np.array([1.0, 0.0, 0.0]),
    )
    assert n is not None and np.degrees(np.arccos(n[2])) < 0.2  # 0.35-2.4 deg at 10 mm


def _counterbore(rng, noise: float, tilt_deg: float = 0.0):
    """A square opening (half width 23.25 mm, the 0.5 mm task's) on the floor of a round
    counterbore 45 mm in radius and 6 mm deep, the part's top face beyond it, tilted about
    x by `tilt_deg`; the floor on the +x side hidden for 2 cm (the peg's shadow, as the
    wrist camera sees it); i.i.d. noise along z."""
    xy = rng.uniform(-0.09, 0.09, size=(12000, 2))
    shadow = (xy[:, 0] > 0.0235) & (xy[:, 0] < 0.0435)
    xy = xy[(np.max(np.abs(xy), axis=1) > 0.0235) & ~shadow]
    z = np.where(np.hypot(xy[:, 0], xy[:, 1]) < 0.045, 0.0, 0.006)
    a = rng.uniform(0, 2 * np.pi, 600)
    wall = np.column_stack([0.045 * np.cos(a), 0.045 * np.sin(a), rng.uniform(0, 0.006, 600)])
    p = np.vstack([np.column_stack([xy, z]), wall])
    p[:, 2] += rng.normal(0.0, noise, len(p))
    R = Rotation.from_euler("x", tilt_deg, degrees=True).as_matrix()
    return p @ R.T, R[:, 2]


def test_a_counterbore_round_the_opening_is_read_from_the_surface_next_to_it():
    """The floor round the opening is the face; a 20 mm ring also holds the counterbore's
    wall and the top face beyond it, and its own dominant plane tilted the fit 3.5-5.3 deg
    on set E's counterbore plate. The narrow ring next to the opening holds the floor."""
    x = np.array([1.0, 0.0, 0.0])
    for seed in range(3):
        rng = np.random.default_rng(seed)
        pts, normal = _counterbore(rng, noise=0.0003, tilt_deg=20.0)
        guess = Rotation.from_euler("y", 3, degrees=True).as_matrix() @ normal
        n = rim_normal(pts, np.zeros(3), guess, 0.02325, rng, square_x=x)
        assert n is not None and _angle(n, normal) < 0.3, _angle(n, normal)


def _recorded_view_errors(name: str, seeds=range(3)) -> list[float]:
    """The rim fit's error (deg) on a recorded fine view in tests/data, over rng seeds."""
    d = np.load(Path(__file__).parent / "data" / name)
    E, true_axis = d["estimate"], d["true_hole"][:3, 2]
    out = []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        n = rim_normal(d["points"], E[:3, 3], E[:3, 2], float(d["half"]), rng, E[:3, 0])
        out.append(np.inf if n is None else _angle(n, true_axis))
    return out


def test_a_face_holding_less_than_half_the_wide_ring_is_still_the_face():
    """A recorded fine view (`ideal`, a development fixture: the opening on a raised face
    that steps down 12 mm 5-10 mm beyond two of its sides, a ramp beyond one corner): the
    lower level fills more than half of the 20 mm ring, and that ring's least-median plane
    was 7.7-8.4 deg off. The 5 or 10 mm ring's plane, grown over the 20 mm one: < 1 deg."""
    errors = _recorded_view_errors("fixture_step_down_view_2.npz")
    assert max(errors) < 1.5, errors


def test_the_ring_that_holds_one_surface_chooses_the_face():
    """A recorded fine view (`d435`, a development fixture: the opening on an island 5-15 mm
    wider than it, the part 20 mm lower beyond): the island's top holds less than half of
    the 10 mm ring, whose least-median plane spans both levels (4.4 mm spread) and, grown,
    ended on the hole's wall (16 deg); the 5 mm ring fits the island's top alone."""
    errors = _recorded_view_errors("fixture_island_d435_view.npz")
    assert max(errors) < 1.5, errors
