"""Where an opening is on its face: a square's centre and yaw, a circle's centre, from the
wrist cloud, by fitting the opening's nominal shape to the cloud round it.

At the pre-insertion pose the wrist camera sees the face round the opening, the far wall
of the hole below it and the tops of the side walls; the peg hides the hole's inside and,
from the camera, the face at the near edge. The opening's shape and size are known (the
task's nominal peg plus clearance). CFVS's fine network infers the hole's position from
the whole crop, and beside raised blocks, ribs or a pocket's walls on bodies unlike its
training ones leaves it millimetres and degrees (yaw) off, which a 0.5 mm clearance does
not forgive.

Here the opening is one model: the face a plane outside the nominal outline, the walls
that outline going down from it. Each point's residual is its distance to that surface,
and the model is moved in the face's plane (and a square turned about its axis) to
minimise a redescending loss of them (scipy's least squares, `arctan`, its scale following
the face's measured noise): what stands beside the opening (a boss's sides, a rib's top,
the hole's floor) counts for almost nothing, and where the peg's shadow hides the face at
one edge no point pulls the model there. The face's level is one more unknown, and so is
how far inside the outline the walls appear (a depth camera's mixed pixels put them
~0.6 mm in), held near zero by a prior. The least squares starts from the best of a grid
of positions and yaws round the estimate (it has local minima a wall's width apart).
There is no opening to fit when the face round it is too noisy to tell, when few points
lie on the fitted outline or more of the face lies inside it than on it (a plain face, a
smaller bore), or when the fit moves the estimate further than OPN's error beside
features (MAX_SHIFT, MAX_TURN_DEG).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from cfvs_maniskill.geometry import robust_sigma

LEVEL_BAND = (0.001, 0.006)
"""The face's level is measured on the points this far outside the estimated opening's
sides: the face right at the edge, not what stands beside it (a rib 1 cm away)."""
SEARCH = 0.008
"""The opening is looked for up to this far either side of the estimate (OPN's error
beside features, 1-6 mm) ..."""
REACH = 0.010
"""... on the points up to this far outside its outline there ..."""
WALL_DEPTH = 0.04
"""... and down to this far below the face (not the hole's floor)."""
GRID = 0.002
"""The least squares starts from the best of a grid of positions this far apart ..."""
GRID_TURN_DEG = (-4.0, -2.0, 0.0, 2.0, 4.0)
"""... and, for a square, these turns."""
SCALE = 0.00075
"""The loss's scale (m): a point this far from the model counts half as much as a near
one ..."""
NOISE_SCALE = 1.5
"""... or this many times the face's measured noise where that is more (0.1-0.6 mm under
the stereo cameras' models at the fine stage's standoff, 1-2 mm under `ideal`)."""
INSET_PRIOR = 0.3
"""How strongly the walls' inset is held at zero, per point's square root ..."""
MAX_INSET = 0.0015
"""... and kept between 0 and this (mixed pixels pull a seen wall inwards, ~0.6 mm in the
simulated cameras; where a calibration error puts it outwards, the centre takes it)."""
EDGE_NEAR = 0.003
"""A fit is used only where the cloud shows its outline: points this near it ..."""
MIN_EDGE_POINTS = 20
"""... at least this many (fewer: the opening is behind a wall, under the peg)."""
MAX_NOISE = 0.002
"""No fit when the face's measured noise (robust sigma along its normal) is above this:
edges are then blurred over several millimetres. Measured on wrist views of the face at
the pre-insertion pose: ideal sensor 0.9-1.9 mm, realistic 0.1-0.6 mm, i.i.d. 3 mm
2.9-9.4 mm."""
FACE_HEIGHT_MAX_NOISE = 0.005
"""The face's height is measured up to this noise (robust sigma): a median over the
hundreds of points beside the opening stays within a few tenths of a millimetre under
noise that blurs its edges (the i.i.d. 3 mm profile measures 2.9-9.4 mm there)."""
MIN_LEVEL_POINTS = 30
"""Fewer points than this beside the opening: the face is not seen well enough."""
MAX_SHIFT = 0.006
"""A fit moving the centre further than this from the estimate is taken for something
else's edge, and not used."""
MAX_TURN_DEG = 6.0
"""... or turning the square further than this."""


def nominal_distance(q: np.ndarray, round_opening: bool) -> np.ndarray:
    """How far each point `q` (..., 2 or 3: x, y in the face) lies from the opening's centre
    in the opening's own shape: Euclidean for a round one, Chebyshev for a square one with
    its sides along x and y, so `< half` is inside."""
    xy = np.abs(q[..., :2])
    return np.hypot(xy[..., 0], xy[..., 1]) if round_opening else xy.max(axis=-1)


def fit_opening(
    points: np.ndarray, frame: np.ndarray, half: float, round_opening: bool = False
) -> np.ndarray | None:
    """The hole frame `frame` (4x4: origin at the estimated opening, z out of the hole along
    the face's normal, x along a side of a square) moved in the face's plane and, for a
    square, turned about its z onto the opening seen in `points` (n, 3, same frame as
    `frame`); None when there is no opening to fit (module docstring). `half`: the
    opening's nominal half width, or its radius with `round_opening`."""
    q = (points - frame[:3, 3]) @ frame[:3, :3]  # the estimate's frame: x, y in the face
    r = nominal_distance(q, round_opening)
    level, spread, _ = _ring_level(q[:, 2], r, half)
    if level is None or spread > MAX_NOISE:
        return None
    depth = level - q[:, 2]
    q = q[(r < half + SEARCH + REACH) & (depth > -REACH) & (depth < WALL_DEPTH)]
    scale = max(SCALE, NOISE_SCALE * spread)
    start = _start(q, half, round_opening, level, scale)
    free = np.delete(start, 2) if round_opening else start  # a circle has no yaw (_model)
    lower = np.full(len(free), -np.inf)
    upper = np.full(len(free), np.inf)
    lower[-1], upper[-1] = 0.0, MAX_INSET
    fit = least_squares(
        _residuals,
        free,
        args=(q, half, round_opening),
        bounds=(lower, upper),
        loss="arctan",
        f_scale=scale,
        x_scale=0.001,
    ).x
    p = _model(fit, round_opening)
    (cx, cy), yaw = p[:2], p[2]
    if not _opening_seen(q, p, half, round_opening, scale):
        return None
    if np.hypot(cx, cy) > MAX_SHIFT or np.degrees(abs(yaw)) > MAX_TURN_DEG:
        return None
    c, s = np.cos(yaw), np.sin(yaw)
    out = frame.copy()
    out[:3, :2] = frame[:3, :2] @ np.array([[c, -s], [s, c]])
    out[:3, 3] = frame[:3, 3] + frame[:3, 0] * cx + frame[:3, 1] * cy
    return out


def _opening_seen(
    q: np.ndarray, p: np.ndarray, half: float, round_opening: bool, scale: float
) -> bool:
    """Whether the cloud `q` shows the opening model `p`: at least MIN_EDGE_POINTS points on
    it near its outline (the face's edge, the walls' tops), and fewer at the face's level
    well inside the outline (a face where the model has its opening) than there."""
    out = _outside(q, p, half, round_opening)
    near = model_distance(q, p, half, round_opening, out) < scale
    edge = np.count_nonzero(near & (np.abs(out + p[4]) < EDGE_NEAR))
    inside = np.count_nonzero((out < -EDGE_NEAR) & (np.abs(q[:, 2] - p[3]) < scale))
    return edge >= MIN_EDGE_POINTS and inside < edge


def _outside(q: np.ndarray, p: np.ndarray, half: float, round_opening: bool) -> np.ndarray:
    """How far each point lies outside the outline of the opening model `p` (centre x, y,
    yaw, ...; or models, (..., 5)), in the face's plane; negative inside. (..., n)."""
    x, y = q[:, 0] - p[..., 0, None], q[:, 1] - p[..., 1, None]
    if not round_opening:
        c, s = np.cos(p[..., 2, None]), np.sin(p[..., 2, None])
        x, y = c * x + s * y, c * y - s * x
    return nominal_distance(np.stack([x, y], axis=-1), round_opening) - half


def model_distance(
    q: np.ndarray, p: np.ndarray, half: float, round_opening: bool, out: np.ndarray | None = None
) -> np.ndarray:
    """Each point's distance to the opening model `p` (centre x, y, yaw, face level, walls'
    inset; in the estimate's frame; or models, (..., 5)): the face outside the outline, the
    walls inside. `out`: `_outside` of the same, where already known."""
    if out is None:
        out = _outside(q, p, half, round_opening)
    z = q[:, 2] - p[..., 3, None]
    face = np.where(out >= 0.0, np.abs(z), np.hypot(out, z))
    w = out + p[..., 4, None]
    wall = np.where(z <= 0.0, np.abs(w), np.hypot(w, z))
    return np.minimum(face, wall)


def _model(free: np.ndarray, round_opening: bool) -> np.ndarray:
    """The model (centre x, y, yaw, face level, walls' inset) of the fitted unknowns: a
    circle has no yaw."""
    return np.insert(free, 2, 0.0) if round_opening else free


def _residuals(free: np.ndarray, q: np.ndarray, half: float, round_opening: bool) -> np.ndarray:
    p = _model(free, round_opening)
    d = model_distance(q, p, half, round_opening)
    return np.append(d, INSET_PRIOR * np.sqrt(len(q)) * p[4])


def _start(q: np.ndarray, half: float, round_opening: bool, level: float, scale: float):
    """The grid's best model (face at `level`, walls not inset) by squares truncated at two
    loss scales `scale`: a far point weighs no more than it will in the least squares."""
    g = np.arange(-SEARCH, SEARCH + 1e-9, GRID)
    turns = [0.0] if round_opening else np.radians(GRID_TURN_DEG)
    yaw, cx, cy = (a.ravel() for a in np.meshgrid(turns, g, g, indexing="ij"))
    grid = np.column_stack([cx, cy, yaw, np.full(len(cx), level), np.zeros(len(cx))])
    cost = np.square(np.minimum(model_distance(q, grid, half, round_opening), 2 * scale))
    return grid[int(np.argmin(cost.sum(axis=1)))]


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
