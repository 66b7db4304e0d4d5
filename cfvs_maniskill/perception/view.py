"""Which of a square peg's four equivalent approach yaws gives the wrist camera a clear view.

The camera rides 11 cm off the tool axis (robots/ur5.py), so at the pre-insertion pose it
looks at the opening from one side, about 8 cm above the face; which side is set by the
peg's yaw. A square peg fits its hole at four yaws 90 deg apart, all the same insertion.
Beside a wall, a post or a tower standing over the face, some of them put that thing
between the camera and the opening: the camera sees the obstacle's back and the fine stage
has nothing to servo on. Before the coarse move, the cloud of the whole scene (seen from
15-30 cm) gives, for each yaw, the points standing above the face near the line from where
the camera will be to the opening (`sight_blockage`). The yaw nearest the tool's own is
kept unless that line is blocked and another is clear, so the wrist turns no more than it
must and nothing changes where nothing stands in the way.
"""

from __future__ import annotations

import numpy as np

from cfvs_maniskill import geometry as G
from cfvs_maniskill.perception.opening import nominal_distance

SIGHT_RADIUS = 0.015
"""Points within this distance of the camera's line of sight to the opening, measured
across the face, may block it (about the half width of the wrist camera's view of the
opening at 8 cm)."""
STANDING = 0.01
"""... if they stand this far above the hole's face, and as high as the line is there: the
face itself (and a coarse axis a few degrees off, which tilts it by millimetres near the
opening) never blocks."""
BLOCKED = 10
"""A line of sight with at least this many such points is blocked: the wall bracket's wall
put 12-450 there (most over 50) from 15-30 cm; a few flying pixels or a grazed edge stay
below."""


AT_OPENING = 0.01
"""`points_at_opening`: points within this of the opening's edge across the face ..."""
AT_OPENING_DEPTH = 0.03
"""... and within this of the face along the axis (its wall's top, a counterbore's floor)."""


def sight_blockage(world: np.ndarray, camera: np.ndarray, hole: np.ndarray) -> int:
    """Points of `world` (K, 3) that reach the line from `camera` (3,) to the opening of
    hole frame `hole` (4x4, z out of the hole).

    The scene is read as a height map over the face: a wall or a post seen from 15-30 cm
    shows its top and the sides facing the camera, rarely the surface the future line of
    sight would cross, but it stands on the face, so a point blocks the line where it is
    within SIGHT_RADIUS of it across the face and at least as high as the line is there."""
    local = (world - hole[:3, 3]) @ hole[:3, :3]
    cam = (camera - hole[:3, 3]) @ hole[:3, :3]
    d = -cam[:2]  # across the face, from the camera's foot to the opening
    t = np.clip((local[:, :2] - cam[:2]) @ d / max(float(d @ d), 1e-12), 0.0, 1.0)
    across = np.linalg.norm(local[:, :2] - (cam[:2] + t[:, None] * d), axis=1)
    line_height = cam[2] * (1.0 - t)
    h = local[:, 2]
    return int(np.count_nonzero((across < SIGHT_RADIUS) & (h > STANDING) & (h >= line_height)))


def approach_yaws(nearest: np.ndarray, tool_x: np.ndarray) -> list[np.ndarray]:
    """The four pre-insertion poses of a square peg: `nearest` (4x4) and the same turned
    about its axis by 90, -90 and 180 deg, ordered by how far the wrist turns to reach them
    from a tool whose x axis is `tool_x` (least first)."""
    x, y = nearest[:3, 0], nearest[:3, 1]
    turns = sorted((x, y, -x, -y), key=lambda a: -float(a @ tool_x))
    return [G.make(G.frame_with_z(nearest[:3, 2], a), nearest[:3, 3]) for a in turns]


def clear_view_yaw(
    world: np.ndarray, poses: list[np.ndarray], camera_in_tcp: np.ndarray, hole: np.ndarray
) -> tuple[int, list[int]]:
    """Index into `poses` (candidate pre-insertion tcp poses, most preferred first) of the
    first whose camera (at `camera_in_tcp`, tcp frame) has a clear line of sight to the
    opening of `hole`, and each candidate's blockage. If none is clear, the first: the
    opening sits in a recess, or the coarse estimate is wrong enough that its "face" cuts
    through the part; either way turning the wrist buys nothing (on part-like bodies the
    least-blocked yaw differed from the nearest by noise-level counts in half the cases
    where the choice mattered)."""
    counts = [sight_blockage(world, P[:3, :3] @ camera_in_tcp + P[:3, 3], hole) for P in poses]
    clear = [i for i, n in enumerate(counts) if n < BLOCKED]
    return (clear[0] if clear else 0), counts


def points_at_opening(
    world: np.ndarray, hole: np.ndarray, half: float, round_opening: bool = False
) -> int:
    """How many points of `world` (K, 3) lie over the opening of hole frame `hole` and its
    rim: within AT_OPENING of its edge (`half`: its nominal half width, or its radius with
    `round_opening`) across the face and of the face along the axis. Behind a wall the
    wrist camera sees the wall's back and none of these."""
    q = (world - hole[:3, 3]) @ hole[:3, :3]
    r = nominal_distance(q, round_opening)
    return int(np.count_nonzero((r < half + AT_OPENING) & (np.abs(q[:, 2]) < AT_OPENING_DEPTH)))
