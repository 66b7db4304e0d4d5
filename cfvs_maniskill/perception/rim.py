"""The face a hole opens on, from the points in a ring around an estimated hole centre.

The asset contract puts every hole's axis along the normal of the planar face it opens on
(`docs/holes.md`). Near the pre-insertion pose the wrist camera sees that face around the
opening closely, so its normal is a direct measurement of the hole's axis, which CFVS's
fine network only infers (and misreads beside a raised block: on a stepped block it turned
the peg 7-10 deg off the axis). Other surfaces can reach into the ring (a step's wall, a
rib, an edge's side face, a lower level), so the face is the surface next to the opening:
the least-median-of-squares plane (no distance threshold to tune per sensor) of the ring
5, 10 or 20 mm wide that fits one closest, grown over the 20 mm ring for precision. The
ring follows the opening's nominal shape: for a square opening its sides (nearest the
opening, where a small face such as a boss's top or a counterbore's floor still is),
falling back to a round ring beyond its corners.
"""

from __future__ import annotations

import numpy as np

from cfvs_maniskill.geometry import angle_deg, robust_sigma

RING_MARGIN = 0.004
"""The ring starts this far outside the opening (its sides, or for the round ring its
farthest point): beyond the chamfer and a few millimetres of error in the estimated
centre."""
SEED_WIDTHS = (0.005, 0.010, 0.020)
"""The face is the surface next to the opening: of the rings this wide, the one whose
least-median plane fits it closest (the smallest robust sigma) says which surface it is.
A ring that holds another surface too fits its best plane with a spread of millimetres
(beside a counterbore's step, a lower level round a small island); one on the face alone
fits it within the sensor's noise. ..."""
RING_WIDTH = 0.020
"""... and that plane is grown over the ring this wide (`_grow`), for precision. With the
20 mm ring alone the face was lost beside a step round the opening (a counterbore's floor
6 mm below the top face, 2 cm out: 3.5-5.3 deg off) or a step down 5-10 mm from an
opening's side (the lower level half the ring: 4-8 deg)."""
RING_BAND = 0.025
"""Only points within this distance of the estimated opening's plane: the face, not the
floor under an edge. Wide, because OPN's estimate of the opening's height can be 1-2 cm
off on bodies unlike its training ones (on a flanged pipe 9 cm tall it put the opening
14-20 mm too low, and a 10 mm band then held no face at all: 4 of 20 inserted in 6-DoF,
20 of 20 at 25 mm; a hexagonal boss 7 -> 19); the walls and the tops of raised blocks a
wide band takes in are outliers to the fit, more than INLIER_SIGMAS from the face."""
MIN_RING_POINTS = 60
INLIER_SIGMAS = 2.5
"""A point within this many noise sigmas of a plane is on it."""
GROW_PASSES = 3
MIN_SIGMA = 0.0002
"""The noise taken for a cloud that shows none (a noise-free render's depth steps)."""
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
    square_x: np.ndarray | None = None,
) -> np.ndarray | None:
    """Unit normal (on `axis`'s side) of the face around the opening estimated at `centre`
    with axis `axis` (out of the hole), from `points` (n, 3, same frame); None when the
    ring holds too few points or its best plane is not the face.

    `opening_radius`: how far the opening reaches from its centre: a round hole's radius,
    a square hole's corner (its half width times sqrt(2)), or, with `square_x` (the square
    opening's x axis), its half width: the ring then follows the square's sides, so it
    starts next to the opening along them instead of beyond its corners."""
    axis = axis / np.linalg.norm(axis)
    n = _face_normal(points, centre, axis, opening_radius, rng, square_x)
    if n is None and square_x is not None:
        # Too little of the face beside the sides is in view (the peg hides it from the
        # wrist camera, or it ends there): the round ring beyond the corners.
        reach = opening_radius * np.sqrt(2)
        n = _face_normal(points, centre, axis, reach, rng, None)
    return n


def _face_normal(
    points: np.ndarray,
    centre: np.ndarray,
    axis: np.ndarray,
    reach: float,
    rng: np.random.Generator,
    square_x: np.ndarray | None = None,
) -> np.ndarray | None:
    """rim_normal on one ring shape: the plane of the flattest of the SEED_WIDTHS rings,
    grown over the RING_WIDTH ring."""

    def ring(normal: np.ndarray, width: float = RING_WIDTH) -> np.ndarray:
        return _ring(points, centre, normal, reach + RING_MARGIN, square_x, width)

    seeds = [s for s in (_plane_inliers(ring(axis, w), rng) for w in SEED_WIDTHS) if s is not None]
    if not seeds:
        return None
    seed = min(seeds, key=lambda fit: fit[1])
    n = _grow(ring, *seed, axis)
    return None if angle_deg(n, axis) > MAX_TURN_DEG else n


def _grow(ring, inliers: np.ndarray, sigma: float, axis: np.ndarray) -> np.ndarray:
    """The normal of the plane of `inliers` (noise `sigma`), refitted GROW_PASSES times to
    the points of the wide ring `ring(normal)` within INLIER_SIGMAS of it, the noise
    measured again on them each time. The ring is cut square to the latest normal: one cut
    across a tilted face keeps, at its edges, only the points whose noise moves them
    inwards, and that truncation tilts the fit back towards the guess (measured: 1.2 deg at
    2 mm noise and a 12 deg wrong guess; 0.2 deg recut). The least-median sigma of a ring a
    third of which is another surface comes out 1.5-2x the noise; measured again on the
    inliers it is the noise, so the band stops taking in the chamfer and the step's edge."""
    n, origin = _plane(inliers, axis)
    for _ in range(GROW_PASSES):
        wide = ring(n)
        r = (wide - origin) @ n
        near = np.abs(r) <= INLIER_SIGMAS * sigma + 1e-6
        if np.count_nonzero(near) < MIN_RING_POINTS // 2:
            break
        n, origin = _plane(wide[near], axis)
        sigma = max(robust_sigma(r[near]), MIN_SIGMA)
    return n


def _plane(points: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares plane of `points`: (unit normal on `axis`'s side, centroid)."""
    origin = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - origin, full_matrices=False)
    n = vt[2]
    return (n if n @ axis >= 0 else -n), origin


def _ring(
    points: np.ndarray,
    centre: np.ndarray,
    axis: np.ndarray,
    inner: float,
    square_x: np.ndarray | None = None,
    width: float = RING_WIDTH,
) -> np.ndarray:
    """The points `width` wide outside `inner` around the axis, near its plane: outside
    a circle of that radius, or with `square_x` a square of that half width."""
    d = points - centre
    h = d @ axis
    across = d - np.outer(h, axis)
    if square_x is None:
        dist = np.linalg.norm(across, axis=1)
    else:
        ex = square_x - (square_x @ axis) * axis
        ex /= np.linalg.norm(ex)
        dist = np.maximum(np.abs(across @ ex), np.abs(across @ np.cross(axis, ex)))
    return points[(dist > inner) & (dist < inner + width) & (np.abs(h) < RING_BAND)]


def _plane_inliers(ring: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, float] | None:
    """The dominant plane's inliers and the noise measured about it (a robust sigma, m),
    or None with too few points. Least median of squares: the plane through 3 random
    points that leaves the smallest median squared distance; its inliers are the points
    within INLIER_SIGMAS robust sigmas (sigma from that median: the sensor's noise,
    whatever the sensor)."""
    if len(ring) < MIN_RING_POINTS:
        return None
    origins, normals = _hypotheses(ring, rng)
    if len(normals) == 0:
        return None
    _, med_best, residual = _least_median(ring, origins, normals)
    sigma = 1.4826 * (1 + 5 / (len(ring) - 3)) * np.sqrt(med_best)
    inliers = ring[np.abs(residual) <= INLIER_SIGMAS * sigma + 1e-6]
    if len(inliers) < MIN_RING_POINTS // 2:
        return None
    return inliers, float(sigma)


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
