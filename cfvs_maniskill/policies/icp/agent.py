"""The ICP baselines (paper, Baselines): register a training cuboid's model to the wrist
cloud with open3d, read the hole off the registered model, then insert open loop.

- `icp`: the registration starts from the model placed at the workspace centre (the paper:
  "the transformation from the end-effector to the centre of the workspace").
- `icp_kpts`: it starts from the hole pose OAKN predicts (CFVS's coarse network).

Both see the same preprocessed cloud as CFVS (table and peg removed, world frame) and keep
only the task's degrees of freedom. The model is a hole file like any other (default: the
paper's 7 x 13 x 13 cm training cuboid), so its hole frame is exact for that body and only
approximate for every other shape: that is the method's limit the paper measures.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d
import trimesh

from cfvs_maniskill import geometry as G
from cfvs_maniskill.constants import PRE_INSERT_HEIGHT
from cfvs_maniskill.objects.build import build_geometry
from cfvs_maniskill.objects.library import load_library
from cfvs_maniskill.perception.clouds import MIN_OBJECT_POINTS, object_points, tool_to_world
from cfvs_maniskill.policies.base import Action, Agent, Observation
from cfvs_maniskill.policies.interface import TaskSpec, insertion_pose
from cfvs_maniskill.task_dof import constrain


@dataclass
class ICPConfig:
    init: str = "workspace"
    """Initial model pose: "workspace" (centre of the workspace) or "oakn" (OAKN's pose)."""
    model: str = "cuboid_train_a"
    """Hole file whose body is registered (the paper: the 7 x 13 x 13 cm training cuboid)."""
    model_points: int = 6000
    """Points sampled on the model's surface."""
    voxel: float = 0.003
    """Observed cloud voxel size, metres (about the camera's pixel footprint at 25 cm)."""
    max_distances: tuple[float, ...] = (0.04, 0.015, 0.006)
    """Coarse-to-fine correspondence distances of the ICP passes, metres."""
    iterations: int = 40
    """ICP iterations per pass."""


def model_cloud(geom, n: int) -> o3d.geometry.PointCloud:
    """Surface samples of a hole body with their face normals, body frame; the bottom face
    rests on the table, is never seen, and is left out."""
    mesh = geom.visual_trimesh()
    pts, faces = trimesh.sample.sample_surface(mesh, 2 * n, seed=0)
    normals = mesh.face_normals[faces]
    keep = ~((normals[:, 2] < -0.99) & (pts[:, 2] < mesh.bounds[0, 2] + 1e-4))
    pts, normals = pts[keep][:n], normals[keep][:n]
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts.astype(np.float64)))
    cloud.normals = o3d.utility.Vector3dVector(normals.astype(np.float64))
    return cloud


class ICPAgent(Agent):
    obs_mode = "pointcloud"
    max_decisions = 2

    def __init__(self, task: TaskSpec, cfg: ICPConfig | None = None):
        self.task = task
        self.cfg = cfg or ICPConfig()
        # One thread: open3d's parallel sums change with the thread count, and so would the
        # episode (same seed -> same result on any machine); the clouds are small.
        o3d.utility.set_max_threads(1)
        if self.cfg.init not in ("workspace", "oakn"):
            raise ValueError(
                f"ICPConfig.init: expected 'workspace' or 'oakn', got {self.cfg.init!r}"
            )
        self.name = "icp" if self.cfg.init == "workspace" else "icp_kpts"
        spec = load_library().select([self.cfg.model], profile=task.peg)[0]
        self.geom = build_geometry(spec, task.peg, task.clearance, task.hole_depth)
        self.model = model_cloud(self.geom, self.cfg.model_points)
        self.model_hole = G.make(np.eye(3), self.geom.hole_frame)
        self.oakn = None
        if self.cfg.init == "oakn":
            from cfvs_maniskill.policies.cfvs.agent import CFVSAgent

            self.oakn = CFVSAgent(task)  # only its coarse stage (OAKN + Algorithm 1) is used
        self.moved = False
        self.fitness = 0.0

    def reset(self, seed: int) -> None:
        self.moved = False
        self.phase, self.estimate = "", None
        if self.oakn is not None:
            self.oakn.reset(seed)

    def initial_object_pose(self, pts: np.ndarray, tcp: np.ndarray) -> np.ndarray | None:
        """The model's starting pose in the world (upright at the workspace centre, or
        placed so that its hole frame sits on OAKN's estimate from the view's tool-frame
        object points `pts`)."""
        if self.oakn is None:
            task = self.task
            centre = [np.mean(task.workspace_x), np.mean(task.workspace_y)]
            z = -float(self.geom.visual_vertices[:, 2].min())
            return G.make(np.eye(3), np.array([*centre, z]))
        H = self.oakn.estimate_hole(pts, tcp)
        if H is None or not np.all(np.isfinite(H)):
            return None
        return H @ G.inv(self.model_hole)

    def register(self, points: np.ndarray, T_init: np.ndarray) -> np.ndarray:
        """World pose of the model body fitted to the observed world points."""
        obs = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points.astype(np.float64)))
        obs = obs.voxel_down_sample(self.cfg.voxel)
        # Register the partial view onto the complete model: every observed point then has
        # a true counterpart, which a model-to-view registration would not.
        T = G.inv(T_init)
        loss = o3d.pipelines.registration.TransformationEstimationPointToPlane()
        crit = o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=self.cfg.iterations)
        for d in self.cfg.max_distances:
            r = o3d.pipelines.registration.registration_icp(obs, self.model, d, T, loss, crit)
            T, self.fitness = np.asarray(r.transformation), float(r.fitness)
        return G.inv(T)

    def act(self, observation: Observation) -> Action:
        if self.moved:
            return Action.insert()
        xyzw = observation.obs["pointcloud"]["xyzw"][0].cpu().numpy()
        tcp = observation.tcp_pose
        pts = object_points(xyzw, tcp, self.task.peg)
        if len(pts) < MIN_OBJECT_POINTS:
            return Action.give_up(f"{self.name}: the camera sees no hole object")
        T_init = self.initial_object_pose(pts, tcp)
        if T_init is None:
            return Action.give_up("OAKN: no initial pose for ICP")
        T_obj = self.register(tool_to_world(pts, tcp), T_init)
        if self.fitness == 0.0:
            return Action.give_up(
                f"{self.name}: no model point within {1000 * self.cfg.max_distances[-1]:.0f} mm "
                "of the cloud after registration"
            )
        H = T_obj @ self.model_hole
        self.moved = True
        self.phase, self.estimate = f"{self.name}: model registered", H
        pose = insertion_pose(self.task.peg, H, -PRE_INSERT_HEIGHT, tcp)
        return Action.move(constrain(self.task, pose, tcp))
