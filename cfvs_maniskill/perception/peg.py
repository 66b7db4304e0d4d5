"""The peg in the wrist cloud: where the camera sees the peg against where the arm holds it.

The peg is rigid on the flange, so the robot knows where it is (forward kinematics); the
camera reports it elsewhere by exactly the error of its own pose (the hand-eye calibration)
and, less, its depth scale. Fitting the peg's known solid to its points gives that error as
a rigid move, and moving the whole cloud by it places the hole where it stands relative to
the peg's tip: a servo on that cloud closes the loop on the peg-to-hole offset the camera
sees, and the mount error cancels (endpoint closed-loop visual servoing; Hutchinson, Hager
& Corke 1996). A camera that does not see the peg (`flange_side`) gives no fit, and the
cloud stays as reported.

The fit is point-to-plane ICP against the planes that bound the peg (robots/peg.py), damped
so that what the points do not show stays put: the turn about a round peg's axis, and the
move along the axis when the tip's end face is out of view (neither moves the opening ahead
of the tip sideways). Faces seen edge-on are left out (MIN_FACE_SHARE); a side face seen
whole is then placed between its drawn edges (`centre_across`): its plane alone does not
say where along it the peg is.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from cfvs_maniskill import geometry as G
from cfvs_maniskill.perception.clouds import near_peg, world_to_tool
from cfvs_maniskill.robots.peg import peg_face_spans, peg_planes

REACH = 0.06
"""Peg points within this length of the tip (tcp frame) are fitted: the part of the peg
next to the opening, clear of the flange and the wrist."""
SEARCH_MARGIN = 0.006
"""First pass: points within this distance of the peg's drawn solid: beyond any hand-eye
error a calibrated cell leaves (a few mm, under a degree at 10 cm)."""
INLIER_SIGMAS = 3.0
"""Later passes: points within this many robust sigmas of the fitted surface ..."""
MIN_INLIER_BAND = 0.0015
"""... and never a narrower band than this (a noise-free cloud's sigma is ~0)."""
MIN_PEG_POINTS = 200
"""Fewer peg points than this: the camera does not see the peg (no fit)."""
MAX_CORRECTION = (0.01, 5.0)
"""A fit that moves the peg further than this (m, deg) found something else: no fit."""
MIN_FACE_SHARE = 0.1
"""A face holding fewer points than this share of the face best in view is left out of the
fit: seen edge-on, its few points are the edge's, and the noise biases which face each of
them is given to (1 mm of noise made a fit that moved the cloud 1 mm from a peg seen
without error)."""
MIN_SPAN_SEEN = 0.8
"""A side face's seen points must span this share of its drawn width (both edges in view)
for the face to be placed across the peg."""
ITERATIONS = 12
DAMPING = 1e-6
"""Per point, added to each diagonal entry of the normal equations: far below what any
direction the points constrain gathers, it keeps the unconstrained ones at zero."""


def peg_correction(
    world: np.ndarray, tcp: np.ndarray, peg: str, chamfer: float = 0.0
) -> np.ndarray | None:
    """The rigid 4x4 move, in the tool (tcp) frame, that puts the peg the cloud `world`
    (K, 3) shows onto the peg the tcp pose `tcp` holds; None when too little of the peg is
    in view. The camera rides on the tool, so the move holds for every view of an episode
    (`apply`): fitted once where nothing stands near the peg, no part is taken for it."""
    p = world_to_tool(world, tcp).astype(np.float64)
    n, d = peg_planes(peg, chamfer)
    p = p[near_peg(p, peg, SEARCH_MARGIN, REACH - SEARCH_MARGIN)]
    if len(p) < MIN_PEG_POINTS:
        return None
    T = np.eye(4)  # seen tcp-frame points -> where the arm holds them
    band = SEARCH_MARGIN
    for _ in range(ITERATIONS):
        q = p @ T[:3, :3].T + T[:3, 3]
        signed = q @ n.T - d  # (M, K) distance to each bounding plane
        face = np.argmax(signed, axis=1)
        r = signed[np.arange(len(q)), face]
        keep = np.abs(r) <= band
        count = np.bincount(face[keep], minlength=len(n))
        fitted = count >= MIN_FACE_SHARE * count.max()
        keep &= fitted[face]
        if keep.sum() < MIN_PEG_POINTS:
            return None
        q, r, nf = q[keep], r[keep], n[face[keep]]
        J = np.hstack([np.cross(q, nf), nf])  # d r / d (turn, move), small-angle
        A = J.T @ J + DAMPING * len(q) * np.eye(6)
        step = np.linalg.solve(A, -J.T @ r)
        dT = G.make(Rotation.from_rotvec(step[:3]).as_matrix(), step[3:])
        T = dT @ T
        sigma = G.robust_sigma(r)
        band = max(INLIER_SIGMAS * sigma, MIN_INLIER_BAND)
        if np.linalg.norm(step[3:]) < 1e-6 and np.linalg.norm(step[:3]) < 1e-5:
            break
    T = centre_across(p, T, n, d, peg_face_spans(peg, chamfer), band, fitted)
    move, turn = np.linalg.norm(T[:3, 3]), np.degrees(Rotation.from_matrix(T[:3, :3]).magnitude())
    if move > MAX_CORRECTION[0] or turn > MAX_CORRECTION[1]:
        return None
    return T


def centre_across(
    p: np.ndarray,
    T: np.ndarray,
    n: np.ndarray,
    d: np.ndarray,
    spans: np.ndarray,
    band: float,
    fitted: np.ndarray,
) -> np.ndarray:
    """`T` moved across the side face with most points within `band` of it, so that the
    points within `band` of its plane sit midway between the face's drawn edges (`spans`).
    From `tip_view` the peg shows one face whole and its neighbours edge-on (left out of the
    fit): the plane fit then leaves the move along the face at zero, and the hand-eye error
    that way with it; the face's edges show it. Unchanged when a `fitted` face already holds
    that direction, the face is narrower than a few bands (a round peg's facets) or its
    points do not reach both edges (MIN_SPAN_SEEN)."""
    q = p @ T[:3, :3].T + T[:3, 3]
    signed = q @ n.T - d
    face = np.argmax(signed, axis=1)
    on = np.abs(signed[np.arange(len(q)), face]) <= band
    count = np.bincount(face[on], minlength=len(n)) * (np.abs(n[:, 2]) < 0.1)  # side faces
    f = int(np.argmax(count))
    width = spans[f, 1] - spans[f, 0]
    if count[f] < MIN_PEG_POINTS or width < 4 * band:
        return T
    t = np.cross([0.0, 0.0, 1.0], n[f])
    if np.any(fitted & (np.abs(n @ t) > 0.5)):
        return T
    # By the plane, not by the nearest face: past a drawn edge, a point is still this face's.
    lo, hi = np.percentile(q[np.abs(signed[:, f]) <= band] @ t, [1, 99])  # robust to strays
    if hi - lo < MIN_SPAN_SEEN * width:
        return T
    return G.make(np.eye(3), (spans[f].mean() - 0.5 * (lo + hi)) * t) @ T


def apply(T: np.ndarray | None, world: np.ndarray, tcp: np.ndarray) -> np.ndarray:
    """World points of a view from tcp pose `tcp` moved by a tool-frame correction
    (`peg_correction`; None: as they are)."""
    if T is None:
        return world
    C = tcp @ T @ G.inv(tcp)
    return (world @ C[:3, :3].T + C[:3, 3]).astype(world.dtype)
