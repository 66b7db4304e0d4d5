"""Where an opening is on its face: a square's centre and yaw, a circle's centre, from the
wrist cloud.

At the pre-insertion pose the wrist camera sees the face round the opening, the far wall
of the hole below it and the tops of the two side walls; the peg hides the hole's inside
and, from the camera, the face at the near edge. The opening's size is known (the task's
nominal peg plus clearance). CFVS's fine network infers the hole's position from the whole
crop, and beside raised blocks, ribs or a pocket's walls on bodies unlike its training
ones leaves it 1-3 mm and 1-3 deg (yaw) off, which a 0.5 mm clearance does not forgive.

Here (in the estimated hole frame, the axis from the rim fit): the face's level is the
densest flat part of a ring just outside the opening (so the band that counts as face
follows the sensor's noise); each side is where the face begins (the half-density point of
the face's points across the side: noise blurs an edge evenly both ways; in a cloud too
sparse for that, as a passive stereo camera's on a plain part, its innermost point with a
neighbour), or, where the camera sees that side's wall, the wall's own points (noise lifts
a seen wall's top into the face's band, inside the edge). The centre is midway between two
opposite sides of the same kind; on the axis the camera looks along, where only the far
wall is seen (a face edge opposite it is the peg's shadow), it is the nominal half width
from that wall, less how much narrower than nominal the two side walls look (measured in
the same view: the simulated camera puts walls ~0.6 mm inside, and a real one has its own
error; with no two walls in view, none). The yaw is the walls' mean slope. A round
opening's centre is a least-squares circle of its known radius through the edge seen in
each sector round it (the face's edge, or the wall's points where the wall is seen), with
how much narrower the walls look than the face's edge as one more unknown, and sectors far
off the circle (the peg's shadow) left out; where the cloud is too sparse for an edge per
sector (a passive stereo camera on a plain part), the circle through the wall's own points.
Measured on 42 wrist views of the 0.5 mm task (ideal sensor, test and held-out objects):
lateral error p50 / p90 1.26 / 2.61 -> 0.35 / 0.86 mm, yaw 0.83 / 2.02 -> 0.19 / 0.55 deg
(docs/cfvs.md).
"""

from __future__ import annotations

from itertools import combinations

import numpy as np

from cfvs_maniskill.geometry import angle_deg, robust_sigma

LEVEL_BAND = (0.001, 0.006)
"""The face's level is measured on the points this far outside the estimated opening's
sides: the face right at the edge, not what stands beside it (a rib 1 cm away)."""
SEARCH = 0.008
"""A side is looked for up to this far either side of the estimated one (OPN's error
beside features, 1-6 mm)."""
MAX_NOISE = 0.002
"""No fit when the face's measured noise (robust sigma along its normal) is above this:
edges are then blurred over several millimetres. Measured on wrist views of the face at
the pre-insertion pose: ideal sensor 0.9-1.9 mm, realistic 0.1-0.6 mm, i.i.d. 3 mm
2.9-9.4 mm, where the fit's lateral error was 2.2 mm (p50) against the network's 0.9."""
FACE_HEIGHT_MAX_NOISE = 0.005
"""The face's height is measured up to this noise (robust sigma): a median over the
hundreds of points beside the opening stays within a few tenths of a millimetre under
noise that blurs its edges (the i.i.d. 3 mm profile measures 2.9-9.4 mm there)."""
MIN_LEVEL_POINTS = 30
"""Fewer points than this beside the opening: the face is not seen well enough."""
MIN_DEPTH_BAND = 0.0015
"""Points within max(this, 4 robust sigmas of the face's noise) of the face's level are
the face; below is the hole, above other surfaces."""
EDGE_BIN = 0.0005
"""A side's edge: the face's point density in bins this wide across it ..."""
EDGE_RUN = 3
"""... the first run of this many bins at half the density further out."""
MIN_EDGE_POINTS = 3
"""A side with fewer face points per bin than this (at its plateau) is too sparse for the
density profile; a square's side then ..."""
SPARSE_EDGE_GAP = 0.002
"""... begins at its innermost face point with another within this further out (a passive
stereo camera on a plain part puts 6-30 points along a side, 1-4 mm apart; a lone point
further in is a stray)."""
WALL_DEPTH = 0.04
"""The wall: points down to this far below the face (not the hole's floor) ..."""
WALL_NEAR = 0.003
"""... within this of the face's edge on that side ..."""
MIN_WALL_POINTS = 20
"""... at least this many of them, else the wall is out of the camera's view."""
CORNER = 0.003
"""Points this close to a corner along a side are left out (the corner belongs to both)."""
MAX_SHIFT = 0.006
"""A fit moving the centre further than this from the estimate is taken for something
else's edge, and not used."""
MAX_TURN_DEG = 6.0
"""... or turning the square further than this."""
CIRCLE_WALL_BAND = WALL_NEAR + SEARCH / 2
"""A round opening's wall points lie within this of the nominal radius round the estimate
(its edge near where it should be, the estimate half a search off)."""
SECTORS = 24
"""A round opening's edge is measured in this many equal sectors round the estimate ..."""
MIN_SECTORS = 8
"""... and a circle fitted only through at least this many of them ..."""
MIN_SECTOR_WALL = 8
"""... a sector's wall counting with this many points (a 15 deg arc of MIN_WALL_POINTS') ..."""
SECTOR_OUTLIER = 0.0005
"""... through the sectors within this of it (the peg's shadow moves a face edge outwards
by millimetres)."""
MIN_CIRCLE_WALL = 40
"""A round opening's centre is fitted to the wall's own points when at least this many are
seen round it ..."""
WALL_ITERATIONS = 8
"""... reweighted this many times ..."""
WALL_MIN_SCALE = 0.0002
"""... the outliers' weight set on their robust spread, taken as at least this (m) ..."""
MIN_WALL_SPREAD = 0.15
"""... and their directions from the centre spanning an arc of about 100 deg or more (the
smaller eigenvalue of their mean outer product: 0.5 all round, 0.15 for 100 deg)."""
MAX_CONDITION = 10.0
"""The walls' narrowing is fitted only when the sectors' equations tell it from the centre
this well (condition number)."""
MIN_SPREAD = 0.25
"""The sectors' directions must surround the centre: the smaller eigenvalue of their mean
outer product at least this (0.5 all round, 0 for one direction)."""
WIDTH_TOLERANCE = (-0.001, 0.004)
"""Two opposite sides are used only when they are 2 x half this far from the opening's
nominal width apart (a chamfered or worn edge is wider; nearer is something else)."""


def nominal_distance(q: np.ndarray, round_opening: bool) -> np.ndarray:
    """How far each point `q` (..., 2 or 3: x, y in the face) lies from the opening's centre
    in the opening's own shape: Euclidean for a round one, Chebyshev for a square one with
    its sides along x and y, so `< half` is inside."""
    xy = np.abs(q[..., :2])
    return np.hypot(xy[..., 0], xy[..., 1]) if round_opening else xy.max(axis=-1)


def fit_opening(
    points: np.ndarray,
    frame: np.ndarray,
    half: float,
    iterations: int = 2,
    round_opening: bool = False,
) -> np.ndarray | None:
    """The hole frame `frame` (4x4: origin at the estimated opening, z out of the hole along
    the face's normal, x along a side of a square) moved in the face's plane and, for a
    square, turned about its z onto the opening seen in `points` (n, 3, same frame as
    `frame`); None when the face and walls round it are not seen well enough, or the fit
    moves it further than MAX_SHIFT / MAX_TURN_DEG. `half`: the opening's nominal half
    width, or its radius with `round_opening`."""
    # Only what the fit can reach (the rest of the cloud is most of it).
    q = (points - frame[:3, 3]) @ frame[:3, :2]
    r = nominal_distance(q, round_opening)
    points = points[r < half + SEARCH + MAX_SHIFT]
    H = frame.copy()
    for _ in range(iterations):
        step = _fit_once(points, H, half, round_opening)
        if step is None:
            return None
        H = step
    shift = H[:3, 3] - frame[:3, 3]
    if np.linalg.norm(shift) > MAX_SHIFT or angle_deg(H[:3, 0], frame[:3, 0]) > MAX_TURN_DEG:
        return None
    return H


def _fit_once(
    points: np.ndarray, H: np.ndarray, half: float, round_opening: bool
) -> np.ndarray | None:
    q = (points - H[:3, 3]) @ H[:3, :3]  # the estimate's frame: x, y in the face, z out
    r = nominal_distance(q, round_opening)
    level, spread, _ = _ring_level(q[:, 2], r, half)
    if level is None or spread > MAX_NOISE:
        return None
    band = max(MIN_DEPTH_BAND, 4.0 * spread)
    face = q[(np.abs(q[:, 2] - level) < band) & (r < half + SEARCH)]
    wall = q[(q[:, 2] < level - band) & (q[:, 2] > level - WALL_DEPTH) & (r < half + SEARCH)]
    fit = _circle(face, wall, half) if round_opening else _square(face, wall, half)
    if fit is None:
        return None
    (cx, cy), yaw = fit
    c, s = np.cos(yaw), np.sin(yaw)
    out = H.copy()
    out[:3, :2] = H[:3, :2] @ np.array([[c, -s], [s, c]])
    out[:3, 3] = H[:3, 3] + H[:3, 0] * cx + H[:3, 1] * cy
    return out


def face_height(
    points: np.ndarray, frame: np.ndarray, half: float, round_opening: bool = False
) -> tuple[float | None, int]:
    """(level, seen): how far along `frame`'s z (m) the face round the opening lies from
    `frame`'s origin (4x4: the estimated opening, z out of the hole along the face's
    normal), from the `seen` points 1-6 mm outside the opening (`half`: its nominal half
    width, or radius with `round_opening`); level None when fewer than MIN_LEVEL_POINTS
    are seen or they are too noisy to tell the face (FACE_HEIGHT_MAX_NOISE)."""
    q = (points - frame[:3, 3]) @ frame[:3, :3]
    r = nominal_distance(q, round_opening)
    level, spread, seen = _ring_level(q[:, 2], r, half)
    if level is None or spread > FACE_HEIGHT_MAX_NOISE:
        return None, seen
    return level, seen


def _ring_level(heights: np.ndarray, r: np.ndarray, half: float):
    """(level, noise sigma, points) of the face on the points whose distance `r` from the
    estimated centre (in the face's plane) is 1-6 mm outside the opening (LEVEL_BAND), from
    their `heights` along the axis; level and sigma None when fewer than MIN_LEVEL_POINTS."""
    near = (r > half + LEVEL_BAND[0]) & (r < half + LEVEL_BAND[1])
    seen = int(np.count_nonzero(near))
    if seen < MIN_LEVEL_POINTS:
        return None, None, seen
    level, spread = face_level(heights[near])
    return level, spread, seen


def face_level(h: np.ndarray, start: float | None = None) -> tuple[float, float]:
    """(level, noise sigma) of the face among heights `h` along the axis: from `start`
    (None: the densest millimetre), the median and the robust spread of the points within
    a window that grows to 3 sigmas. Beside the opening the ring also holds fins' and ribs'
    tops and, where the estimate is off, the hole's wall; the face is the flat, dense part."""
    if start is None:
        counts, edges = np.histogram(h, bins=max(1, int(np.ptp(h) / 0.001) + 1))
        i = int(np.argmax(counts))
        start = float(edges[i] + edges[i + 1]) / 2
    level, window = start, 0.003
    sigma = 0.0
    for _ in range(3):
        near = h[np.abs(h - level) < window]
        level = float(np.median(near))
        sigma = robust_sigma(near, level)
        window = max(0.003, 3.0 * sigma)
    return level, sigma


def edge_crossing(inward: np.ndarray, half: float) -> float | None:
    """Where the face begins along one side's inward distances `inward` (its points within
    SEARCH of the nominal edge): the first bin from the axis at which the face's point
    density reaches half its plateau and stays there, refined by that bin's fill. Noise
    blurs the edge evenly both ways, so the half-density point is the edge itself."""
    w = inward - half
    counts, lo = np.histogram(w, bins=int(round(2 * SEARCH / EDGE_BIN)), range=(-SEARCH, SEARCH))
    plateau = float(np.percentile(counts, 75))
    if plateau < MIN_EDGE_POINTS:
        return None
    full = counts >= plateau / 2
    # From the axis outwards, the first run of EDGE_RUN bins all at half the plateau.
    runs = np.convolve(full.astype(int), np.ones(EDGE_RUN, int), "valid") == EDGE_RUN
    if not runs.any():
        return None
    i = int(np.argmax(runs))
    fill = min(1.0, counts[i] / plateau)
    return half + float(lo[i]) + EDGE_BIN * (1.0 - fill)


def _sparse_edge(inward: np.ndarray, half: float) -> float | None:
    """Where a sparse face begins along one side: its innermost point that has another
    within SPARSE_EDGE_GAP further out; None with fewer than MIN_EDGE_POINTS points in all
    (the same count as a dense side's per bin). Noise moves points both ways across the
    edge, so the two sides of an opening share the error and their midpoint keeps the
    centre."""
    u = np.sort(inward[inward > half - SEARCH])
    close = np.flatnonzero(np.diff(u) < SPARSE_EDGE_GAP)
    return float(u[close[0]]) if len(u) >= MIN_EDGE_POINTS and len(close) else None


def _square(face: np.ndarray, wall: np.ndarray, half: float):
    """((cx, cy), yaw) of a square opening from the face points `face` and the points below
    the face `wall` (its frame), or None."""
    centre = [0.0, 0.0]
    slopes, weights = [], []
    sides = {}
    for axis in (0, 1):
        other = 1 - axis
        for sign in (1.0, -1.0):
            u = sign * face[:, axis]  # inward distance along this side's normal...
            v = face[:, other]  # ... and position along the side
            on = (u > half - SEARCH) & (np.abs(v) < half - CORNER)
            edge = edge_crossing(u[on], half)
            edge = _sparse_edge(u[on], half) if edge is None else edge
            # Where the camera sees this side's wall, noise lifts the wall's top into the
            # face's band, inside the edge: the wall's own points say where it is.
            wu, wv = sign * wall[:, axis], wall[:, other]
            ref = half if edge is None else edge
            seen = (np.abs(wv) < half - CORNER) & (np.abs(wu - ref) < WALL_NEAR)
            is_wall = np.count_nonzero(seen) >= MIN_WALL_POINTS
            if is_wall:
                edge = float(np.median(wu[seen]))
                slope = _line_slope(wv[seen], wu[seen])
                # The side's normal turned by yaw: its inward distance changes along the
                # side by -sign * tan(yaw) for the x sides, +sign * tan(yaw) for the y sides.
                slopes.append(np.arctan(slope) * (-sign if axis == 0 else sign))
                weights.append(np.count_nonzero(seen))
            if edge is not None:
                sides[axis, sign] = (edge, is_wall)
    if not sides:
        return None
    # How much narrower the walls look than the nominal opening, from an axis with both
    # walls in view (the cloud's own error at walls, the same on every wall); with none,
    # the walls are where the camera puts them (a stereo cloud's far wall: 0.1 mm inside).
    narrowing = [
        half - (sides[a, 1.0][0] + sides[a, -1.0][0]) / 2
        for a in (0, 1)
        if (a, 1.0) in sides and (a, -1.0) in sides and sides[a, 1.0][1] and sides[a, -1.0][1]
    ] or [0.0]
    for axis in (0, 1):
        plus, minus = sides.get((axis, 1.0)), sides.get((axis, -1.0))
        # Both sides the same kind: a face edge beside a wall may be the edge of the peg's
        # shadow (the near side, which the peg hides from the wrist camera).
        if plus is not None and minus is not None and plus[1] == minus[1]:
            width = plus[0] + minus[0]
            if 2 * WIDTH_TOLERANCE[0] <= width - 2 * half <= 2 * WIDTH_TOLERANCE[1]:
                centre[axis] = (plus[0] - minus[0]) / 2
                continue
        # One wall only (the peg hides the near side's edge from the wrist camera): the
        # opening's nominal half width beyond it, less the narrowing measured across the
        # other axis.
        walls = [(sg, s[0]) for sg, s in ((1.0, plus), (-1.0, minus)) if s is not None and s[1]]
        if len(walls) == 1:
            sg, at = walls[0]
            centre[axis] = sg * (at - (half - float(np.mean(narrowing))))
    yaw = float(np.average(slopes, weights=weights)) if weights else 0.0
    return (centre[0], centre[1]), yaw


def _circle(face: np.ndarray, wall: np.ndarray, radius: float):
    """((cx, cy), 0) of a round opening of `radius` from the face points `face` and the
    points below the face `wall` (its frame), or None: from one edge per sector round it
    (`_sector_circle`) where the cloud is dense enough to draw them, else from the wall's
    own points (`_wall_circle`: a passive stereo camera on a plain part fills a few points
    per sector)."""
    fit = _sector_circle(face, wall, radius)
    if fit is not None:
        return fit
    near = wall[np.abs(np.linalg.norm(wall[:, :2], axis=1) - radius) < CIRCLE_WALL_BAND]
    return _wall_circle(near[:, :2], radius) if len(near) >= MIN_CIRCLE_WALL else None


def _wall_circle(p: np.ndarray, radius: float):
    """((cx, cy), 0): the circle of `radius` through the wall points `p` (x, y), by
    iteratively reweighted least squares (Tukey's biweight on their robust spread: the
    hole's floor and a counterbore's wall count for nothing); None when too few agree or
    they span too short an arc (MIN_WALL_SPREAD).
    The walls are taken where the camera puts them: on sparse stereo clouds their
    narrowing is not told from the centre, and was measured there as 0 +- 0.4 mm."""
    c = np.zeros(2)
    w = np.ones(len(p))
    for _ in range(WALL_ITERATIONS):
        d = p - c
        rho = np.maximum(np.linalg.norm(d, axis=1), 1e-9)
        sw = np.sqrt(w)
        c = c + np.linalg.lstsq(d / rho[:, None] * sw[:, None], (rho - radius) * sw, rcond=None)[0]
        res = np.linalg.norm(p - c, axis=1) - radius
        scale = max(WALL_MIN_SCALE, robust_sigma(res))
        w = (1.0 - np.clip(res / (4.685 * scale), -1.0, 1.0) ** 2) ** 2
    d = p[w > 0] - c
    dirs = d / np.linalg.norm(d, axis=1)[:, None]
    if len(d) < MIN_CIRCLE_WALL or np.linalg.eigvalsh(dirs.T @ dirs / len(d))[0] < MIN_WALL_SPREAD:
        return None
    return (float(c[0]), float(c[1])), 0.0


def _sector_circle(face: np.ndarray, wall: np.ndarray, radius: float):
    """((cx, cy), 0) of a round opening of `radius` from the face points `face` and the
    points below the face `wall` (its frame), or None. Each sector gives one edge: where
    its wall is seen, the wall's median distance (noise lifts the wall's top into the
    face's band, inside the edge), else where the face begins (edge_crossing)."""
    width = 2 * np.pi / SECTORS
    # Each point's angle and distance round the estimate, once for all sectors.
    polar = [
        (np.arctan2(p[:, 1], p[:, 0]), np.linalg.norm(p[:, :2], axis=1), kind)
        for p, kind in ((wall, 1.0), (face, 0.0))
    ]
    rows, edges = [], []
    for k in range(SECTORS):
        mid = -np.pi + (k + 0.5) * width
        u = np.array([np.cos(mid), np.sin(mid)])
        for a, dist, kind in polar:
            in_sector = np.abs((a - mid + np.pi) % (2 * np.pi) - np.pi) < width / 2
            rho = dist[in_sector]
            if kind:
                rho = rho[np.abs(rho - radius) < CIRCLE_WALL_BAND]
                if len(rho) < MIN_SECTOR_WALL:
                    continue
                edge = float(np.median(rho))
            else:
                edge = edge_crossing(rho[rho > radius - SEARCH], radius)
                if edge is None:
                    continue
            rows.append([u[0], u[1], -kind])  # walls: the edge less their narrowing
            edges.append(edge - radius)
            break
    A, b = np.array(rows).reshape(-1, 3), np.array(edges)
    if len(b) < MIN_SECTORS:
        return None
    # The walls' narrowing is an unknown only where the sectors tell it from the centre
    # (walls beside face edges, or walls all round), else taken as none.
    cols = [0, 1, 2] if np.linalg.cond(A) < MAX_CONDITION else [0, 1]
    A = A[:, cols]
    # The circle most sectors agree with, from every minimal set of them (about 2000 small
    # solves; the whole fit takes ~6 ms): the peg's shadow moves several sectors' face edge
    # outwards by millimetres, and a least-squares fit through them all would follow it.
    sets = np.array(list(combinations(range(len(b)), len(cols))))
    M = A[sets]
    solvable = np.abs(np.linalg.det(M)) > 1e-3
    if not solvable.any():
        return None
    trial = np.linalg.solve(M[solvable], b[sets[solvable]][..., None])[..., 0]
    off = np.abs(trial @ A.T - b)
    agree = off < SECTOR_OUTLIER
    # Most sectors agreeing; of those, the smallest summed distance (metres: below 1).
    best = int(np.argmax(agree.sum(axis=1) - np.where(agree, off, 0.0).sum(axis=1)))
    keep = agree[best]
    if keep.sum() < MIN_SECTORS:
        return None
    full = np.zeros(3)
    full[cols] = np.linalg.lstsq(A[keep], b[keep], rcond=None)[0]
    dirs = A[keep, :2]
    if np.linalg.eigvalsh(dirs.T @ dirs / len(dirs))[0] < MIN_SPREAD:
        return None
    return (float(full[0]), float(full[1])), 0.0


def _line_slope(x: np.ndarray, y: np.ndarray) -> float:
    """dy/dx of a line through the points, by least squares refitted without the points
    beyond 3 robust sigmas of the first fit (a corner's or a chamfer's)."""
    keep = np.ones(len(x), bool)
    slope = 0.0
    for _ in range(2):
        xm, ym = x[keep].mean(), y[keep].mean()
        dx = x[keep] - xm
        slope = float(dx @ (y[keep] - ym) / max(float(dx @ dx), 1e-12))
        res = y - ym - slope * (x - xm)
        sigma = robust_sigma(res[keep], 0.0) + 1e-9
        keep = np.abs(res) < 3 * sigma
    return slope
