"""The face a hole opens on, from the points in a ring around an estimated hole centre.

The asset contract puts every hole's axis along the normal of the planar face it opens on
(`docs/holes.md`). Near the pre-insertion pose the wrist camera sees that face around the
opening closely, so its normal is a direct measurement of the hole's axis, which CFVS's
fine network only infers (and misreads beside a raised block: on a stepped block it turned
the peg 7-10 deg off the axis). Other surfaces can reach into the ring (a step's wall, a
rib, an edge's side face), so the plane is fitted by least median of squares: no distance
threshold to tune per sensor, right while the face holds more than half the ring's points.
"""

from __future__ import annotations

import numpy as np

RING_MARGIN = 0.004
"""The ring starts this far outside the opening's farthest point (its corner for a square
hole): beyond the chamfer and a few millimetres of error in the estimated centre."""
RING_WIDTH = 0.020
"""... and is this wide."""
RING_BAND = 0.010
"""Only points within this distance of the estimated opening's plane: the face, not the
tops of raised blocks or the floor under an edge."""
MIN_RING_POINTS = 60
HYPOTHESES = 200
"""Random point triples tried by the least-median-of-squares fit."""
MAX_TURN_DEG = 20.0
"""A fitted normal further than this from the estimate is taken for another surface."""


def rim_normal(
    points: np.ndarray,
    centre: np.ndarray,
    axis: np.ndarray,
    opening_radius: float,
    rng: np.random.Generator,
) -> np.ndarray | None:
    """Unit normal (on `axis`'s side) of the face around the opening estimated at `centre`
    with axis `axis` (out of the hole), from `points` (n, 3, same frame); None when the
    ring holds too few points or its best plane is not the face.

    `opening_radius`: the opening's farthest point from its centre (the hole's half width,
    times sqrt(2) for a square hole)."""
    axis = axis / np.linalg.norm(axis)
    n, guess = None, axis
    # Twice: the second time with the ring cut square to the face found. A ring cut across
    # a tilted face keeps, at its edges, only the points whose noise moves them inwards,
    # and that truncation tilts the fit back towards the guess (measured: 1.2 deg at 2 mm
    # noise and a 12 deg wrong guess; 0.2 deg after the second pass).
    for _ in range(2):
        fit = _plane_normal(_ring(points, centre, guess, opening_radius + RING_MARGIN), guess, rng)
        if fit is None:
            break
        n = guess = fit
    if n is None or np.degrees(np.arccos(np.clip(n @ axis, -1.0, 1.0))) > MAX_TURN_DEG:
        return None
    return n


def _ring(points: np.ndarray, centre: np.ndarray, axis: np.ndarray, inner: float) -> np.ndarray:
    """The points RING_WIDTH wide outside radius `inner` around the axis, near its plane."""
    d = points - centre
    h = d @ axis
    radial = np.linalg.norm(d - np.outer(h, axis), axis=1)
    return points[(radial > inner) & (radial < inner + RING_WIDTH) & (np.abs(h) < RING_BAND)]


def _plane_normal(ring: np.ndarray, axis: np.ndarray, rng: np.random.Generator):
    """The dominant plane's unit normal (on `axis`'s side), or None with too few points."""
    if len(ring) < MIN_RING_POINTS:
        return None
    # Least median of squares: the plane through 3 random points that leaves the smallest
    # median squared distance; then a least-squares fit to the points within 2.5 robust
    # sigmas of it (sigma from that median: the sensor's noise, whatever the sensor).
    origins, normals = _hypotheses(ring, rng)
    if len(normals) == 0:
        return None
    _, med_best, residual = _least_median(ring, origins, normals)
    sigma = 1.4826 * (1 + 5 / (len(ring) - 3)) * np.sqrt(med_best)
    inliers = ring[np.abs(residual) <= 2.5 * sigma + 1e-6]
    if len(inliers) < MIN_RING_POINTS // 2:
        return None
    _, _, vt = np.linalg.svd(inliers - inliers.mean(axis=0), full_matrices=False)
    n = vt[2]
    return n if n @ axis >= 0 else -n


def _hypotheses(ring: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """HYPOTHESES planes through random point triples of the ring: (origins, unit normals),
    each (h, 3), degenerate (collinear) triples left out."""
    tri = ring[rng.integers(len(ring), size=(HYPOTHESES, 3))]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norms = np.linalg.norm(normals, axis=1)
    ok = norms > 1e-9
    return tri[ok, 0], normals[ok] / norms[ok, None]


def _signed_distances(ring: np.ndarray, origins: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Signed distances (h, n) of the ring's points to the planes (origin, unit normal)."""
    return ((ring[None] - origins[:, None]) @ normals[..., None])[..., 0]


def _least_median(ring: np.ndarray, origins: np.ndarray, normals: np.ndarray):
    """(index, median squared distance, signed distances of the ring to it) of the plane
    with the least median squared distance; ties go to the first, as np.argmin does.

    The same answer, bit for bit, as taking the median of every hypothesis's squared
    distances (what an episode's rim fit cost most of its time on: ~2000 points x 200
    planes), but those medians are computed only for the planes that can win. A few likely
    winners, ranked on every 16th point, set a bound b; a plane whose lower middle squared
    distance exceeds b has a median above b and is skipped. That test runs on distances
    computed in another order, which may differ from the exact ones in the last bits, so
    it keeps a margin far above that rounding."""
    n = len(ring)
    # |n . p - n . o| for every plane and point, by broadcasting rather than a matrix
    # product: BLAS would start threads, which stall when eval workers fill the cores.
    cols = np.ascontiguousarray(ring.T)
    approx = normals[:, 0:1] * cols[0]  # (h, n)
    approx += normals[:, 1:2] * cols[1]
    approx += normals[:, 2:3] * cols[2]
    approx -= np.einsum("ij,ij->i", origins, normals)[:, None]
    np.abs(approx, out=approx)
    likely = np.argsort(np.median(approx[:, ::16], axis=1), kind="stable")[:4]
    bound = np.median(_signed_distances(ring, origins[likely], normals[likely]) ** 2, axis=1).min()
    # Both distances carry rounding of a few units of the dtype's precision times the
    # coordinates' size; the margin is many times that.
    margin = 64 * np.finfo(approx.dtype).eps * float(np.abs(ring).max() + np.abs(origins).max() + 1)
    within = np.count_nonzero(approx <= np.sqrt(bound) + margin, axis=1)
    lower_middle = (n - 1) // 2  # the median is at least the sorted value at this index
    can_win = np.flatnonzero(within > lower_middle)
    residual = _signed_distances(ring, origins[can_win], normals[can_win])
    med = np.median(residual**2, axis=1)
    i = int(np.argmin(med))  # can_win is in index order, so ties still go to the first
    return int(can_win[i]), med[i], residual[i]


def align_axis(H: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """The hole frame H (4x4) turned by the smallest rotation that takes its z to `normal`,
    about its own origin."""
    z = H[:3, 2]
    v = np.cross(z, normal)
    s, c = np.linalg.norm(v), float(z @ normal)
    out = H.copy()
    if s < 1e-12:
        return out
    k = v / s
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    R = np.eye(3) + s * K + (1 - c) * (K @ K)  # Rodrigues
    out[:3, :3] = R @ H[:3, :3]
    return out
