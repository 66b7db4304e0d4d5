"""The peg's solid, from the robot's drawing: the URDF's convex peg mesh and, for the agent
that measures the peg in its own cloud, the planes that bound it. Light: numpy and trimesh."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import trimesh

from cfvs_maniskill.constants import PEG_LENGTH, ROUND_PEG_RADIUS, SQUARE_PEG_SIDE


def chamfered_peg_mesh(profile: str, chamfer: float) -> trimesh.Trimesh:
    """The peg as a convex solid in tool0 coordinates (flange at z = 0, tip at z = PEG_LENGTH)
    with its tip edges cut at 45 deg by `chamfer` metres: the tip face is 2 x chamfer narrower,
    so it starts into a tight hole with that much more lateral / yaw error, and the chamfer
    then slides on the hole's edge and centres the peg (design for assembly)."""
    L = PEG_LENGTH
    if profile == "round":
        a = np.linspace(0, 2 * np.pi, 128, endpoint=False)
        # Circumscribe the true circle at the full radius: the polygon's flats then sit
        # 0.0075 mm inside it, negligible against any clearance a task file accepts.
        ring = np.stack([np.cos(a), np.sin(a)], 1) * ROUND_PEG_RADIUS / np.cos(np.pi / 128)
        rings = [(ring, 0.0), (ring, L - chamfer), (ring * (1 - chamfer / ROUND_PEG_RADIUS), L)]
    else:
        h = SQUARE_PEG_SIDE / 2
        sq = np.array([[h, h], [-h, h], [-h, -h], [h, -h]])
        rings = [(sq, 0.0), (sq, L - chamfer), (sq * (h - chamfer) / h, L)]
    pts = np.concatenate([np.c_[xy, np.full(len(xy), z)] for xy, z in rings])
    return trimesh.convex.convex_hull(pts)


@lru_cache(maxsize=8)
def peg_planes(profile: str, chamfer: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(normals (K, 3), offsets (K,)) of the planes bounding the peg in the peg-tip (tcp)
    frame, outward: a point x is inside when every n . x - d <= 0, and the largest of those
    is its signed distance to the surface (exact inside, and near a face outside)."""
    mesh = chamfered_peg_mesh(profile, chamfer)
    n = np.asarray(mesh.face_normals, dtype=np.float64)
    v = np.asarray(mesh.vertices, dtype=np.float64)[mesh.faces[:, 0]] - [0.0, 0.0, PEG_LENGTH]
    d = np.einsum("ij,ij->i", n, v)
    key = np.round(np.c_[n, d], 9)  # a hull's faces come in coplanar pairs: one plane each
    _, first = np.unique(key, axis=0, return_index=True)
    return n[np.sort(first)], d[np.sort(first)]


@lru_cache(maxsize=8)
def peg_face_spans(profile: str, chamfer: float = 0.0) -> np.ndarray:
    """(K, 2): for each plane of `peg_planes`, where its face starts and ends across the
    peg's axis, along z x normal (tcp frame); (0, 0) for the end faces."""
    mesh = chamfered_peg_mesh(profile, chamfer)
    v = np.asarray(mesh.vertices, dtype=np.float64) - [0.0, 0.0, PEG_LENGTH]
    n, d = peg_planes(profile, chamfer)
    spans = np.zeros((len(n), 2))
    for k in range(len(n)):
        across = v[np.abs(v @ n[k] - d[k]) < 1e-9] @ np.cross([0.0, 0.0, 1.0], n[k])
        spans[k] = across.min(), across.max()
    return spans
