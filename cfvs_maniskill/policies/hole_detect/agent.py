"""3DRHD baseline (after Nigro et al. 2020, "Peg-in-hole using 3D workpiece reconstruction
and CNN-based hole detection"): open loop, from the whole scene's point cloud, estimate
where the hole is and along which direction to insert, then insert. No refinement.

Nigro et al. find the hole with a CNN in the image and fit the surrounding surface in the
point cloud; the paper runs it on the whole scene. Here, with geometry from open3d:
1. RANSAC planes (open3d `segment_plane`) peeled off the scene one after another; the
   support plane (horizontal at the table's height) is the table, not a workpiece face.
2. On each plane, its inliers are rasterised in the plane's own 2D coordinates; a hole is
   an empty region fully enclosed by surface (scipy `binary_fill_holes`) whose area is
   that of the hole the robot's peg needs (half to twice), and that is compact.
3. The hole's centre is the region's centroid on the plane; the insertion direction is
   the plane's normal (towards the camera). For a square peg the hole's in-plane axes are
   those of the region's minimum-area bounding rectangle (our addition: the original
   handles round holes; without it every square task would fail by construction).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d
from scipy import ndimage

from cfvs_maniskill import geometry as G
from cfvs_maniskill.constants import PRE_INSERT_HEIGHT, hole_half_extent
from cfvs_maniskill.perception.clouds import (
    MIN_OBJECT_POINTS,
    fit_table,
    object_points,
    tool_to_world,
)
from cfvs_maniskill.policies.base import Action, Agent, Observation
from cfvs_maniskill.policies.interface import TaskSpec, insertion_pose
from cfvs_maniskill.task_dof import constrain


@dataclass
class HoleDetectConfig:
    plane_sigmas: float = 3.0
    """RANSAC inlier distance, in sigmas of the depth noise measured on the table (fitted
    to the cloud, so it follows the sensor attached)."""
    min_plane_distance: float = 0.001
    """... but at least this, metres."""
    max_planes: int = 5
    """Planes peeled off the scene before giving up."""
    min_plane_points: int = 60
    """Smaller planes are noise."""
    cell: float = 0.003
    """Raster cell on a plane, metres (about the camera's pixel footprint)."""
    area_range: tuple[float, float] = (0.5, 2.0)
    """Accepted hole-area ratio to the peg's hole cross-section."""


@dataclass
class HoleCandidate:
    frame: np.ndarray  # 4x4 world hole frame, z out of the surface
    area_ratio: float
    plane_points: int


def _plane_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(n, a)
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


def _rectangle_axis(cells: np.ndarray) -> float:
    """Angle (rad, in [0, pi/2)) of the minimum-area bounding rectangle of 2D points."""
    angles = np.radians(np.arange(0.0, 90.0, 1.0))
    best, best_area = 0.0, np.inf
    for a in angles:
        c, s = np.cos(a), np.sin(a)
        p = cells @ np.array([[c, -s], [s, c]])
        area = np.ptp(p[:, 0]) * np.ptp(p[:, 1])
        if area < best_area:
            best, best_area = a, area
    return float(best)


def holes_on_plane(
    points: np.ndarray, n: np.ndarray, d: float, peg: str, clearance: float, cfg: HoleDetectConfig
) -> list[HoleCandidate]:
    """Enclosed, hole-sized empty regions among one plane's inlier points."""
    u, v = _plane_basis(n)
    uv = np.stack([points @ u, points @ v], axis=1)
    lo = uv.min(axis=0) - 2 * cfg.cell
    ij = np.floor((uv - lo) / cfg.cell).astype(int)
    shape = ij.max(axis=0) + 3
    if shape[0] * shape[1] > 4_000_000:
        return []
    occ = np.zeros(shape, dtype=bool)
    occ[ij[:, 0], ij[:, 1]] = True
    occ = ndimage.binary_closing(occ, iterations=1)  # bridge single missing samples
    gaps, count = ndimage.label(ndimage.binary_fill_holes(occ) & ~occ)
    half = hole_half_extent(peg, clearance)
    hole_area = np.pi * half**2 if peg == "round" else (2 * half) ** 2
    out = []
    for k in range(1, count + 1):
        cells = np.argwhere(gaps == k)
        ratio = len(cells) * cfg.cell**2 / hole_area
        if not cfg.area_range[0] <= ratio <= cfg.area_range[1]:
            continue
        xy = (cells + 0.5) * cfg.cell + lo
        extent = np.ptp(xy, axis=0).max()
        if extent > 2.5 * half * np.sqrt(2):  # long slivers are shadows, not holes
            continue
        centre = xy.mean(axis=0)
        p = centre[0] * u + centre[1] * v - d * n  # the point on the plane n.x + d = 0
        if peg == "square":
            a = _rectangle_axis(xy - centre)
            x = np.cos(a) * u + np.sin(a) * v
        else:
            x = u
        out.append(HoleCandidate(G.make(G.frame_with_z(n, x), p), ratio, len(points)))
    return out


def detect_hole(
    world: np.ndarray, camera: np.ndarray, peg: str, clearance: float, cfg: HoleDetectConfig
) -> HoleCandidate | None:
    """The most hole-like enclosed gap on any plane of the scene, or None."""
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(world.astype(np.float64)))
    o3d.utility.random.seed(0)
    distance = max(cfg.plane_sigmas * fit_table(world).sigma, cfg.min_plane_distance)
    candidates: list[HoleCandidate] = []
    for _ in range(cfg.max_planes):
        if len(cloud.points) < cfg.min_plane_points:
            break
        (a, b, c, d), idx = cloud.segment_plane(distance, 3, 500)
        if len(idx) < cfg.min_plane_points:
            break
        pts = np.asarray(cloud.points)[idx]
        cloud = cloud.select_by_index(idx, invert=True)
        n = np.array([a, b, c])
        scale = np.linalg.norm(n)
        n, d = n / scale, d / scale
        if np.dot(camera - pts.mean(axis=0), n) < 0:  # face the camera: out of the surface
            n, d = -n, -d
        if n[2] > np.cos(np.radians(10)) and abs(pts[:, 2].mean()) < 0.01:
            continue  # the support plane (table) carries no hole
        candidates += holes_on_plane(pts, n, d, peg, clearance, cfg)
    if not candidates:
        return None
    return min(candidates, key=lambda h: abs(np.log(h.area_ratio)))


class HoleDetectAgent(Agent):
    name = "3drhd"
    obs_mode = "pointcloud"
    max_decisions = 2

    def __init__(self, task: TaskSpec, cfg: HoleDetectConfig | None = None):
        self.task = task
        self.cfg = cfg or HoleDetectConfig()
        # One thread: open3d's parallel sums change with the thread count, and so would the
        # episode (same seed -> same result on any machine); the clouds are small.
        o3d.utility.set_max_threads(1)
        self.moved = False

    def reset(self, seed: int) -> None:
        self.moved = False
        self.phase, self.estimate = "", None

    def act(self, observation: Observation) -> Action:
        if self.moved:
            return Action.insert()
        task = self.task
        xyzw = observation.obs["pointcloud"]["xyzw"][0].cpu().numpy()
        tcp = observation.tcp_pose
        # The whole scene as the camera saw it, less the robot's own peg (object_points keeps
        # the table out; it goes back in so that the plane search sees the real scene).
        pts = object_points(xyzw, tcp, task.peg, keep_table=True)
        if len(pts) < MIN_OBJECT_POINTS:
            return Action.give_up("3DRHD: the camera sees nothing but the peg")
        camera = tcp[:3, 3]
        hole = detect_hole(tool_to_world(pts, tcp), camera, task.peg, task.clearance, self.cfg)
        if hole is None:
            return Action.give_up("3DRHD: no hole-sized enclosed gap on any plane of the scene")
        self.moved = True
        self.phase, self.estimate = "3DRHD: hole detected on a plane", hole.frame
        pose = insertion_pose(task.peg, hole.frame, -PRE_INSERT_HEIGHT, tcp)
        return Action.move(constrain(task, pose, tcp))
