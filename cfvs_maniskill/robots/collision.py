"""The arm's own collision model: the convex hull of every link (and the peg) in its link's
frame, posed by forward kinematics, to tell whether a joint configuration would touch a
known obstacle (points seen by the camera, the table's plane). A robot's controller knows
this much from its URDF; nothing here reads the simulated world."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import ConvexHull, cKDTree

from cfvs_maniskill import geometry as G


@dataclass
class LinkHull:
    index: int
    """The link's index in the articulation (and in Pinocchio's link order)."""
    name: str
    faces: np.ndarray
    """(F, 4) outward face planes in the link frame: n . p + d <= 0 inside."""
    vertices: np.ndarray
    """(V, 3) hull vertices in the link frame."""
    centre: np.ndarray
    radius: float
    """The hull's bounding sphere in the link frame."""

    def inside(self, points: np.ndarray, T: np.ndarray, margin: float) -> np.ndarray:
        """Mask of the world `points` within `margin` of the hull posed at T."""
        local = (points - T[:3, 3]) @ T[:3, :3]  # world -> link frame
        return (local @ self.faces[:, :3].T + self.faces[:, 3] <= margin).all(axis=1)


def _shape_vertices(shape) -> np.ndarray:
    """A PhysX collision shape's vertices in its link's frame (convex meshes, boxes, and
    cylinders as 32-sided prisms around their circle, along the shape's x as PhysX has it)."""
    if hasattr(shape, "half_size"):
        h = np.asarray(shape.half_size, np.float64)
        v = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T * h
    elif hasattr(shape, "half_length"):
        a = np.linspace(0, 2 * np.pi, 32, endpoint=False)
        r = shape.radius / np.cos(np.pi / 32)  # the prism contains the cylinder
        ring = np.c_[np.zeros(32), r * np.cos(a), r * np.sin(a)]
        v = np.concatenate([ring + [-shape.half_length, 0, 0], ring + [shape.half_length, 0, 0]])
    else:
        v = np.asarray(shape.vertices, np.float64) * np.asarray(shape.scale, np.float64)
    return v @ G.to_matrix(shape.local_pose)[:3, :3].T + G.to_matrix(shape.local_pose)[:3, 3]


class ArmCollision:
    def __init__(self, robot, kinematics, on_table: tuple[str, ...] = ("base_link",)):
        """`robot`: a ManiSkill Articulation; `kinematics`: its ArmKinematics; links whose
        name ends in one of `on_table` stand on the table and are not checked against it."""
        self.kinematics = kinematics
        self.hulls: list[LinkHull] = []
        self.on_table = set()
        for i, link in enumerate(robot._objs[0].get_links()):
            shapes = link.get_collision_shapes()
            if not shapes:
                continue
            v = np.concatenate([_shape_vertices(s) for s in shapes])
            hull = ConvexHull(v)
            v = v[hull.vertices]
            centre = v.mean(axis=0)
            radius = float(np.linalg.norm(v - centre, axis=1).max())
            self.hulls.append(LinkHull(i, link.name, hull.equations, v, centre, radius))
            if link.name.endswith(on_table):
                self.on_table.add(i)

    def touches(
        self,
        q: np.ndarray,
        points: np.ndarray,
        tree: cKDTree | None,
        margin: float,
        table_z: float = 0.0,
        skip: tuple[str, ...] = (),
    ) -> str | None:
        """The name of the first link that comes within `margin` of a known point (`tree`
        over `points`, world frame) or of the table's plane at `table_z`; None if none.
        Links whose name ends in one of `skip` are not checked."""
        hit = self.first_touch([q], points, tree, margin, table_z, skip)
        return None if hit is None else hit[1]

    def first_touch(
        self,
        qs: list[np.ndarray],
        points: np.ndarray,
        tree: cKDTree | None,
        margin: float,
        table_z: float = 0.0,
        skip: tuple[str, ...] = (),
        chunk: int = 32,
    ) -> tuple[int, str] | None:
        """`touches` for configurations in order: (index of the first that touches, its
        first link's name), or None. Checked `chunk` configurations at a time in one
        query of the point tree, which is what a path check costs."""
        hulls = [h for h in self.hulls if not h.name.endswith(skip)] if skip else self.hulls
        indices = [h.index for h in hulls]
        reach = np.array([h.radius + margin for h in hulls])
        centre = np.array([h.centre for h in hulls])  # bounding-sphere centres, link frames
        for begin in range(0, len(qs), chunk):
            poses = np.array(
                [self.kinematics.link_poses(q, indices) for q in qs[begin : begin + chunk]]
            )
            R, t = poses[:, :, :3, :3], poses[:, :, :3, 3]  # (n, links, ...)
            hit = np.zeros(poses.shape[:2], bool)
            for k, h in enumerate(hulls):
                if h.index not in self.on_table:
                    low = (h.vertices @ R[:, k, 2].T).min(axis=0) + t[:, k, 2]
                    hit[:, k] = low < table_z + margin
            if tree is not None:
                centres = np.einsum("nkij,kj->nki", R, centre) + t
                near = tree.query_ball_point(centres, np.broadcast_to(reach, hit.shape))
                for n, k in zip(*np.nonzero(~hit), strict=True):
                    if near[n, k]:
                        hit[n, k] = hulls[k].inside(points[near[n, k]], poses[n, k], margin).any()
            if hit.any():
                n, k = np.argwhere(hit)[0]
                return begin + int(n), hulls[k].name
        return None

    def on_arm(self, q: np.ndarray, points: np.ndarray, margin: float) -> np.ndarray:
        """Mask of the points (world) within `margin` of the arm at joints q: what a camera
        sees of the robot itself, which is no obstacle."""
        mask = np.zeros(len(points), bool)
        poses = self.kinematics.link_poses(q, [h.index for h in self.hulls])
        for h, T in zip(self.hulls, poses, strict=True):
            centre = T[:3, :3] @ h.centre + T[:3, 3]
            near = np.flatnonzero(np.linalg.norm(points - centre, axis=1) <= h.radius + margin)
            mask[near[h.inside(points[near], T, margin)]] = True
        return mask


def surface_points(geometry, count: int = 4000) -> np.ndarray:
    """Points on a hole object's surface (its body frame), about 1 cm apart on a 20 cm
    body, with its vertices: enough for an arm link (5 cm and more across) to contain some
    wherever it crosses the body. Drawn with a fixed seed: the same for every episode."""
    mesh = geometry.visual_trimesh()
    sampled, _ = trimesh.sample.sample_surface(mesh, count, seed=0)
    return np.concatenate([np.asarray(mesh.vertices, np.float64), sampled])
