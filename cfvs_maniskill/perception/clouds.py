"""Point-cloud preprocessing shared by data collection and the agents, so both see the same.

The wrist cloud arrives in the world frame with w = 0 for empty pixels. Every network here
reads it in the **tool frame** (the peg-tip `tcp` frame, z along the peg): the camera is
fixed to the tool, so this is the camera's own view up to a constant transform, and labels
(keypoints, offsets, actions) become functions of the observation alone. The robot knows its
table and its peg, so their points carry no information about the hole and are dropped
before sampling; what is left is the hole object, at full point budget.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cfvs_maniskill.constants import PEG_LENGTH, peg_half_extent
from cfvs_maniskill.geometry import robust_sigma

TABLE_BAND = 0.02
"""The table plane is fitted to points within this height of its nominal top (z = 0): a
hand-eye error tilts and shifts it by millimetres, never by centimetres."""
TABLE_SIGMAS = 6.0
"""Points less than this many noise sigmas above the fitted table are the table (the noise
scale is measured on the table itself, so this follows whatever sensor is attached)."""
MIN_TABLE_MARGIN = 0.002
"""... but never closer than this (a noise-free cloud still has the table's render error)."""
PEG_MARGIN = 0.004
"""Points within this distance of the peg's known volume are the peg itself."""
MIN_OBJECT_POINTS = 32
"""Fewer object points than this is no usable view: collection redraws, agents give up."""
MAX_RANGE = 0.5
"""Points further than this from the tool are beyond any hole the task places (init error
<= 30 cm plus the object): the far robot base and table edges, dropped."""
FINE_CROP_RADIUS = 0.08
"""Fine stage: keep points within this distance of the tool axis ..."""
FINE_CROP_Z = (-0.02, 0.14)
"""... and between these heights along it (tool frame; the hole is ~3 cm ahead of the tip)."""


def valid_world_points(xyzw: np.ndarray) -> np.ndarray:
    """(M, 4) or (1, M, 4) xyzw -> (K, 3) world points that saw something."""
    x = np.asarray(xyzw, dtype=np.float32).reshape(-1, 4)
    keep = x[:, 3] > 0
    for axis in range(3):  # column by column: np.all(..., axis=1) costs 2.5x more here
        keep &= np.isfinite(x[:, axis])
    return x[keep, :3]


@dataclass(frozen=True)
class TableFit:
    """The table's plane as the camera sees it: n . x = offset (n up), and the spread of
    its points about that plane (the depth noise there, metres)."""

    normal: np.ndarray
    offset: float
    sigma: float

    def height(self, points: np.ndarray) -> np.ndarray:
        return points @ self.normal - self.offset

    @property
    def margin(self) -> float:
        """Height above the plane below which a point counts as the table."""
        return max(TABLE_SIGMAS * self.sigma, MIN_TABLE_MARGIN)


NOMINAL_TABLE = TableFit(np.array([0.0, 0.0, 1.0]), 0.0, 0.001)
"""When too little of the table is in view to fit it: the nominal top, 1 mm of noise."""


_RECENT_FITS: list[tuple[np.ndarray, int, tuple[int, ...], TableFit]] = []
"""The last few fits with their clouds, `min_points` and the point counts it was checked
against: the agent's table calibration and the planner both fit the raw coarse view, and
an identical cloud taking the same branches gives the identical fit (one fit of ~2.8 ms
fewer per episode; nothing else is shared)."""


def fit_table(world: np.ndarray, min_points: int = 200) -> TableFit:
    """Fit the table's plane to the world points near its nominal top: least squares,
    then twice more on the points within 3 robust sigmas (objects standing on it, flying
    pixels and the hole's walls are outliers), the sigma from the median absolute residual."""
    for cloud, used, counts, fit in _RECENT_FITS:
        same_branches = all((c < used) == (c < min_points) for c in counts)
        if same_branches and cloud.shape == world.shape and np.array_equal(cloud, world):
            return fit
    fit, counts = _fit_table(world, min_points)
    _RECENT_FITS.insert(0, (world.copy(), min_points, counts, fit))
    del _RECENT_FITS[3:]
    return fit


def _fit_table(world: np.ndarray, min_points: int) -> tuple[TableFit, tuple[int, ...]]:
    """fit_table's fit, and the point counts it compared with `min_points`."""
    band = world[np.abs(world[:, 2]) < TABLE_BAND].astype(np.float64)
    counts = [len(band)]
    if len(band) < min_points:
        return NOMINAL_TABLE, tuple(counts)
    keep, kept = band, None
    normal, offset, sigma = NOMINAL_TABLE.normal, 0.0, NOMINAL_TABLE.sigma
    for i in range(3):
        counts.append(len(keep))
        if len(keep) < min_points:
            break
        # z = a x + b y + c, least squares
        A = np.column_stack([keep[:, 0], keep[:, 1], np.ones(len(keep))])
        (a, b, c), *_ = np.linalg.lstsq(A, keep[:, 2], rcond=None)
        scale = np.sqrt(a * a + b * b + 1.0)
        normal, offset = np.array([-a, -b, 1.0]) / scale, c / scale
        r = band @ normal - offset
        sigma = max(robust_sigma(r), 1e-5)
        inliers = np.abs(r) < 3 * sigma
        if i == 2 or (kept is not None and np.array_equal(inliers, kept)):
            break  # no next pass, or it would fit the same points to the same plane
        keep, kept = band[inliers], inliers
    normal.flags.writeable = False  # a remembered fit is handed out again
    return TableFit(normal, float(offset), sigma), tuple(counts)


def world_to_tool(points: np.ndarray, tcp: np.ndarray) -> np.ndarray:
    """World points (K, 3) -> tool frame of the 4x4 tcp pose."""
    R, t = tcp[:3, :3], tcp[:3, 3]
    return ((points - t) @ R).astype(np.float32)


def tool_to_world(points: np.ndarray, tcp: np.ndarray) -> np.ndarray:
    return (points @ tcp[:3, :3].T + tcp[:3, 3]).astype(np.float32)


def object_points(
    xyzw: np.ndarray, tcp: np.ndarray, peg: str, keep_table: bool = False
) -> np.ndarray:
    """Tool-frame points of everything but the table (unless `keep_table`) and the peg.

    The table is the plane fitted to the cloud itself (`fit_table`), with a margin of its
    measured noise: the cloud may come from any sensor profile and calibration."""
    return world_object_points(valid_world_points(xyzw), tcp, peg, keep_table)


def world_object_points(
    world: np.ndarray, tcp: np.ndarray, peg: str, keep_table: bool = False
) -> np.ndarray:
    """`object_points` of a cloud's world points that saw something (valid_world_points)."""
    if not keep_table:
        table = fit_table(world)
        world = world[table.height(world) > table.margin]
    p = world_to_tool(world, tcp)
    p = p[np.linalg.norm(p, axis=1) <= MAX_RANGE]
    return p[~near_peg(p, peg, PEG_MARGIN)]


def near_peg(p: np.ndarray, peg: str, margin: float, length: float = PEG_LENGTH) -> np.ndarray:
    """Mask of the tool-frame points `p` within `margin` of the peg's volume, of its last
    `length` before the tip."""
    half = peg_half_extent(peg) + margin
    if peg == "round":
        across = np.hypot(p[:, 0], p[:, 1]) <= half
    else:
        across = (np.abs(p[:, 0]) <= half) & (np.abs(p[:, 1]) <= half)
    return across & (p[:, 2] >= -length - margin) & (p[:, 2] <= margin)


def fine_crop(points: np.ndarray) -> np.ndarray:
    """The paper's crop around the end-effector: tool-frame points near the tool axis."""
    r = np.hypot(points[:, 0], points[:, 1])
    z = points[:, 2]
    return points[(r <= FINE_CROP_RADIUS) & (z >= FINE_CROP_Z[0]) & (z <= FINE_CROP_Z[1])]


def sample_fixed(points: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Exactly n points: a random subset, or all of them plus random repeats if too few.

    Raises ValueError on an empty cloud (the camera saw no object): there is nothing to learn
    from or act on, and callers turn that into a clear failure.
    """
    k = len(points)
    if k == 0:
        raise ValueError("the cloud has no object points (camera sees no hole object)")
    if k >= n:
        idx = rng.choice(k, n, replace=False)
    else:
        idx = np.concatenate([np.arange(k), rng.choice(k, n - k, replace=True)])
    return points[idx]
