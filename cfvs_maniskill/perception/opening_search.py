"""Where the opening is on its face, searched for: the task's nominal opening matched to the
cloud round a coarse estimate.

OAKN votes the hole's keypoints from the whole view; on bodies unlike its training ones (a
wall or a tall step beside the opening, a plate wider than any it saw) its estimate lands
5-20 mm and more off, and the fine stage then starts outside what OPN was trained on.
The opening itself is simple to describe: a hole of known shape and size in a flat face.
Here the cloud round the estimate is read as a grid over the estimate's face plane, and the
opening is put where that template fits best: the ring just outside it is face (points at
one level), and inside it no point is at or above that level while some are below it (the
hole's wall or floor seen through it). Cells the camera did not see count for nothing, so
an opening half hidden by a wall or by the peg still matches. The face's level is tried at
each of the densest levels in the window (OAKN's height can be centimetres off beside a
wall). The best place is taken only when it stands out (MIN_SCORE, MARGIN): a counterbore,
a second pocket or a groove beside the opening can fit nearly as well, and then the
estimate is left as it was. The fine stage's fit (perception/opening.py) reaches a few
millimetres; `locate_opening` gives it this search's reach.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from cfvs_maniskill.perception.opening import face_level, fit_opening, nominal_distance

CELL = 0.002
"""The grid's cell (m), at least; coarser where the cloud is sparser (a passive stereo
camera on a plain part), about one point per cell on average: cells much finer than the
points' spacing leave the face full of holes."""
RADIUS = 0.04
"""The opening is looked for this far round the estimate (m): OAKN's error on the
development bodies (docs/cfvs.md) was below it in 9 of 10 looks."""
DEPTH_WINDOW = 0.08
"""Only points this close to the estimate's face plane (m): OAKN's height was up to 7 cm
off beside walls."""
BAND = 0.003
"""A point within this of the face's level (m), or within 3 sigmas of its measured noise,
is face; further below, inside the opening."""
RING = (0.002, 0.010)
"""The template's ring: this far outside the opening's edge (m, from, to) must be face ..."""
INNER_MARGIN = 0.002
"""... and this far inside it nothing may be at or above the face."""
LEVELS = 3
"""Face levels tried: the densest 2 mm height bins, ..."""
MIN_LEVEL_SHARE = 0.1
"""... each with at least this share of the densest one's points."""
MIN_RING_SEEN = 0.3
"""A place is scored only where the camera saw at least this share of its ring ..."""
FULL_RING_SEEN = 0.6
"""... (a ring seen less than this counts in proportion) ..."""
MIN_BELOW = 3
"""... and at least this many cells below the face inside it (a hole, not a shadow)."""
MIN_SCORE = 0.2
"""The best place is taken when its score (the ring's face share less the inside's share
at or above the face) is at least this ..."""
MARGIN = 0.3
"""... and this much above the best place more than a half width away from it."""


def search_opening(
    points: np.ndarray, frame: np.ndarray, half: float, round_opening: bool = False
) -> np.ndarray | None:
    """The hole frame `frame` (4x4: origin at the estimated opening, z out of the hole along
    the face's normal) moved in its face plane onto the opening of nominal half width (or
    radius, `round_opening`) `half` that `points` (n, 3, world) show within RADIUS of it,
    and along z onto that opening's face; None when no place stands out."""
    q = (points - frame[:3, 3]) @ frame[:3, :3]
    extent = RADIUS + half + RING[1] + 2 * CELL
    q = q[(np.abs(q[:, :2]).max(axis=1) < extent) & (np.abs(q[:, 2]) < DEPTH_WINDOW)]
    if len(q) == 0:
        return None
    cell = max(CELL, 2 * extent / np.sqrt(len(q)))
    n = int(np.ceil(2 * extent / cell))
    cells = np.clip(((q[:, :2] + extent) / cell).astype(int), 0, n - 1)

    def occupied(mask: np.ndarray) -> np.ndarray:
        grid = np.zeros((n, n))
        grid[cells[mask, 0], cells[mask, 1]] = 1.0
        return grid

    ring, inner = _template(half, round_opening, cell)
    if not ring.any() or not inner.any():
        return None  # cells as coarse as the ring: too few points to tell an opening
    centres = np.arange(n) * cell - extent + cell / 2
    cx, cy = np.meshgrid(centres, centres, indexing="ij")
    near = np.hypot(cx, cy) <= RADIUS
    seen = occupied(np.ones(len(q), bool))
    ring_seen = _correlate(seen, ring)
    inner_seen = np.maximum(_correlate(seen, inner), 1.0)
    cover = ring_seen / ring.sum()
    best = None
    for level in _levels(q[:, 2]):
        level, sigma = face_level(q[:, 2], level)
        band = max(BAND, 3.0 * sigma)
        face = _correlate(occupied(np.abs(q[:, 2] - level) < band), ring)
        blocked = _correlate(occupied(q[:, 2] > level - band), inner) / inner_seen
        below = _correlate(occupied(q[:, 2] <= level - band), inner)
        fit = face / np.maximum(ring_seen, 1.0) * np.minimum(1.0, cover / FULL_RING_SEEN)
        ok = near & (cover >= MIN_RING_SEEN) & (below >= MIN_BELOW)
        score = np.where(ok, fit - blocked, -np.inf)
        k = np.unravel_index(int(np.argmax(score)), score.shape)
        if best is None or score[k] > best[0]:
            best = (float(score[k]), k, level, score)
    if best is None or best[0] < MIN_SCORE:
        return None
    top, k, level, score = best
    away = np.hypot(cx - cx[k], cy - cy[k]) > half
    if away.any() and top - float(score[away].max()) < MARGIN:
        return None
    out = frame.copy()
    out[:3, 3] = frame[:3, 3] + frame[:3, :3] @ np.array([cx[k], cy[k], level])
    return out


def locate_opening(
    points: np.ndarray, frame: np.ndarray, half: float, round_opening: bool = False
) -> np.ndarray | None:
    """The opening fitted on its face near hole frame `frame` (perception/opening.py) or,
    where no fit is found there, searched for within RADIUS of it and fitted where the
    search puts it; None when neither finds it. The fit reaches a few millimetres: on the
    `manifolds` development bodies, where three fine looks in a row fitted no opening, OPN's
    estimate was 1-5 cm off and none of those episodes inserted."""
    found = fit_opening(points, frame, half, round_opening)
    if found is None and (near := search_opening(points, frame, half, round_opening)) is not None:
        found = fit_opening(points, near, half, round_opening)
    return found


def _template(half: float, round_opening: bool, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """The ring and inside masks of the nominal opening on a grid of `cell`."""
    m = int(np.ceil((half + RING[1]) / cell))
    u = np.arange(-m, m + 1) * cell
    x, y = np.meshgrid(u, u, indexing="ij")
    r = nominal_distance(np.stack([x, y], axis=-1), round_opening)
    ring = ((r > half + RING[0]) & (r < half + RING[1])).astype(float)
    return ring, (r < half - INNER_MARGIN).astype(float)


def _correlate(grid: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """How many of `mask`'s cells are set in `grid`, with the mask centred on each cell."""
    return ndimage.correlate(grid, mask, mode="constant")


def _levels(heights: np.ndarray) -> list[float]:
    """The LEVELS densest 2 mm bins of `heights`, at least 4 mm apart."""
    counts, edges = np.histogram(heights, bins=max(1, int(np.ptp(heights) / 0.002) + 1))
    out: list[float] = []
    for i in np.argsort(counts)[::-1]:
        if counts[i] < MIN_LEVEL_SHARE * counts.max() or len(out) == LEVELS:
            break
        level = float(edges[i] + edges[i + 1]) / 2
        if all(abs(level - o) > 2 * 0.002 for o in out):
            out.append(level)
    return out
