"""The peg-in-hole task, parameterised by a task file and registered once per file."""

from __future__ import annotations

from typing import Any

import numpy as np
import sapien
import torch
from mani_skill.envs.sapien_env import BaseEnv
from mani_skill.sensors.camera import CameraConfig
from mani_skill.utils.structs.types import SceneConfig, SimConfig

from cfvs_maniskill import geometry as G
from cfvs_maniskill.envs.options import check_options, depth_noise, start_distance
from cfvs_maniskill.envs.scene import sample_object_pose, sample_start, score, solvable_start
from cfvs_maniskill.envs.state import read_task_state, task_state, unflatten
from cfvs_maniskill.envs.table import build_table
from cfvs_maniskill.envs.task_config import TaskConfig, load_task
from cfvs_maniskill.objects.build import build_geometry
from cfvs_maniskill.objects.library import load_library
from cfvs_maniskill.rendering import device
from cfvs_maniskill.rendering.views import aim_at_hole, human_camera_configs
from cfvs_maniskill.robots.collision import ArmCollision, surface_points
from cfvs_maniskill.robots.kinematics import ArmKinematics, body_pose
from cfvs_maniskill.robots.poses import flange_pose, insertion_pose
from cfvs_maniskill.robots.ur5 import CAMERA_FOV, STEREO_UIDS, TCP_LINK, TOOL_LINK, robot_uid_for
from cfvs_maniskill.sensing.model import SensorModel
from cfvs_maniskill.sensing.profile import load_profile, with_mount
from cfvs_maniskill.sensing.wrench import contact_wrench
from cfvs_maniskill.sensing.wrist import WristSensing, camera_geometry

PARK = np.array([0.0, 5.0, -3.0])
"""Unused hole objects wait here, out of every camera's view."""
MAX_INIT_TRIES = 100


class PegInsertEnv(BaseEnv):
    """
    **Task Description:**
    A UR5 carries a peg (round r 23 mm or square 46 mm, 100 mm long) rigidly on its flange
    and must insert it into the hole of a hole object; an RGB-D camera on the wrist sees the
    hole past the peg. Holes are the peg plus the task's clearance (4 mm) and 45 mm deep.

    **Randomizations:**
    - the hole object, among the task's objects (names or splits of `assets/holes/`);
    - its position on the table (workspace_x / workspace_y), its yaw (yaw_deg) and the tilt
      of the hole axis from vertical (tilt_deg, any azimuth);
    - the peg's start: its tip `init_error` metres (15 cm small, 30 cm large) from the hole's
      centre, within `init_cone_deg` of the hole axis, pointing at the hole +- init_aim_deg,
      rolled +- init_roll_deg. A scene is resampled until inverse kinematics reaches the
      start, the pre-insertion and the fully inserted pose, so every scene is solvable.
    - the sensors, by the `sensor` profile (`sensors/<name>.yaml`; default `ideal`, the
      paper's N(0, 1 mm^2) per point; `realistic`: a stereo depth camera's errors, a
      hand-eye calibration error, a noisy wrist force/torque sensor; docs/sensing.md).

    **Success Conditions:**
    From true poses, in the hole's frame: the peg tip is within 5 mm of the hole's bottom,
    inside the hole's cross-section, with the peg axis within 10 degrees of the hole axis.
    A peg on the rim or beside the object is a failure.

    Observations: `state` (robot qpos/qvel, tcp pose, true hole pose), `rgbd`, `pointcloud`.
    The point cloud (`obs["pointcloud"]["xyzw"]`, shape (1, H*W, 4)) is the wrist camera's
    depth back-projected into the **world frame**, metres, with w = 0 for pixels that saw
    nothing (the far plane), as the sensor profile reports it. `wrist_wrench()` is the
    wrist force/torque sensor. Agents see only a `robot_view` of all this
    (policies/interface.py); the true hole pose in `state` is for the oracle and for training.
    """

    task: TaskConfig | None = None  # set on each registered subclass, or by task_file=
    SUPPORTED_ROBOTS = ["ur5_peg_square", "ur5_peg_round"]

    def __init__(
        self,
        *args,
        objects: list[str] | tuple[str, ...] | None = None,
        assets: list[str] | tuple[str, ...] = (),
        init_error: str | float = "small",
        depth_noise_std: float | None = None,
        sensor: str | None = None,
        robot_uids: str | None = None,
        render_backend: str | None = None,
        num_envs: int = 1,
        stereo: bool = False,
        task_file: str | None = None,
        camera_mount: str | None = None,
        **kwargs,
    ):
        if task_file is not None:  # this env's task is the file's, whatever the id's
            self.task = load_task(task_file)
        if self.task is None:
            raise ValueError(
                "PegInsert-v1 needs task_file=PATH (a task file like those in tasks/); "
                "or make a registered task, e.g. PegInsert6DoF-v1"
            )
        cfg = self.task
        check_options(cfg, str(kwargs.get("obs_mode", "")), stereo, num_envs)
        self.stereo = stereo
        """True: the wrist camera also delivers its stereo imagers' lit views (`STEREO_UIDS`;
        the right one the sensor profile's `imager.stereo_baseline` from the left)."""
        self.init_error_m = start_distance(cfg, init_error)
        self.sensor_profile = with_mount(load_profile(sensor), camera_mount)
        """The sensor profile (`sensors/<name>.yaml`): depth camera, hand-eye, wrench; its
        mount replaced by `camera_mount` (a named one) for an agent trained on that
        mount's views (its `env_options`)."""
        self.depth_noise_std = depth_noise(cfg, self.sensor_profile, depth_noise_std)
        self.sensing = SensorModel(self.sensor_profile, self.depth_noise_std)
        self.camera_mount = self.sensor_profile.camera_mount
        """Where the wrist camera sits on the tool (the profile's `mount`)."""
        self.camera_geometry = camera_geometry(cfg, self.sensor_profile)
        """(width, height, vertical fov) of the wrist camera: the profile's field of view."""
        self.wrist = WristSensing(self.sensing, self.depth_noise_std, *self.camera_geometry[:2])
        library = load_library(assets)
        self.object_specs = library.select(list(objects or cfg.objects), profile=cfg.peg)
        self.object_names = [s.name for s in self.object_specs]
        self.geometries = [
            build_geometry(s, cfg.peg, cfg.clearance, cfg.hole_depth) for s in self.object_specs
        ]
        self.object_index = 0
        self.defer_obs = False
        """While True, steps return an empty observation and render nothing (the executor
        sets it during moves: agents only look after a move ends, so rendering every
        control step would be wasted time)."""
        self.episode_info: dict[str, Any] = {}
        self._init_error_m = 0.0
        robot_uids = robot_uids or robot_uid_for(cfg.peg, cfg.peg_chamfer)
        if robot_uids not in self.SUPPORTED_ROBOTS:  # a chamfered peg's robot, made on demand
            self.SUPPORTED_ROBOTS = [*self.SUPPORTED_ROBOTS, robot_uids]
        super().__init__(
            *args,
            robot_uids=robot_uids,
            num_envs=1,
            render_backend=device.render_backend(render_backend),
            **kwargs,
        )

    # ------------------------------------------------------------------ configuration
    @property
    def _default_sim_config(self):
        # 500 Hz physics keeps a 4 mm-clearance peg from tunnelling; 20 Hz control.
        # A 2 mm contact offset (ManiSkill's default is 20 mm): with 20 mm, PhysX's
        # speculative contacts between the peg's bottom face and the hole's rim pushed back
        # a perfectly centred peg; a 2 mm offset still catches 10 mm/s at 500 Hz.
        # Tight-fit tasks use half their clearance; PCM is off everywhere (TaskConfig's
        # contact_offset and pcm say why). 40 position iterations (ManiSkill's 15 let a
        # peg the insertion pressed into the floor at a slight tilt sink 0.06-0.09 mm into
        # a wall; the episode's wall time did not change).
        return SimConfig(
            sim_freq=500,
            control_freq=20,
            scene_config=SceneConfig(
                contact_offset=self.task.contact_offset,
                enable_pcm=self.task.pcm,
                solver_position_iterations=40,
            ),
        )

    @property
    def _default_sensor_configs(self):
        # The wrist camera belongs to the robot (robots/ur5.py). With `stereo`, the camera
        # body also delivers its two imagers' lit grey images: the left one where the wrist
        # camera is, the right one `stereo_baseline` along the image's x (SAPIEN's camera
        # -y). They use ManiSkill's lit "default" shader: the wrist camera's fast "minimal"
        # shader draws every face in its flat colour, so a hole's opening would not show.
        if not self.stereo:
            return []
        return [
            CameraConfig(
                uid=uid,
                pose=self.wrist.imager_pose(uid),
                width=self.task.camera_width,
                height=self.task.camera_height,
                fov=CAMERA_FOV,
                near=0.01,
                far=2.0,
                mount=self.agent.robot.links_map[TOOL_LINK],
                shader_pack="default",
            )
            for uid in STEREO_UIDS
        ]

    @property
    def _default_human_render_camera_configs(self):
        return human_camera_configs()

    def _aim_cameras(self) -> None:
        aim_at_hole(self._human_render_cameras, self.hole_pose)

    def _load_agent(self, options: dict):
        super()._load_agent(options, sapien.Pose())
        a = self.agent
        a.camera_width, a.camera_height, a.camera_fov = self.camera_geometry
        a.camera_mount = self.camera_mount

    def _load_scene(self, options: dict):
        self.table = build_table(self.scene)
        self.hole_objects = []
        for i, (spec, geom) in enumerate(zip(self.object_specs, self.geometries, strict=True)):
            visual, parts = geom.mesh_files()
            b = self.scene.create_actor_builder()
            b.add_visual_from_file(
                str(visual),
                material=sapien.render.RenderMaterial(base_color=[*spec.color[:3], 1.0]),
            )
            for p in parts:
                b.add_convex_collision_from_file(str(p))
            b.initial_pose = sapien.Pose(p=PARK + [0, i, 0])
            self.hole_objects.append(b.build_kinematic(name=f"hole_{spec.name}"))
        self.kinematics = ArmKinematics(self.agent.robot, TCP_LINK)
        self.collision = ArmCollision(self.agent.robot, self.kinematics)
        self._surfaces = [surface_points(g) for g in self.geometries]
        self.wrist.learn_surfaces(
            self.table, self.agent.robot, self.hole_objects, self.object_specs
        )

    # ------------------------------------------------------------------ kinematics
    def tcp_matrix(self) -> np.ndarray:
        """True world pose of the peg tip frame (z along the peg, out of the flange)."""
        return G.to_matrix(body_pose(self.agent.tcp))

    def flange_matrix(self) -> np.ndarray:
        """True world pose of the flange (tool0): the tcp frame PEG_LENGTH back along z."""
        return flange_pose(self.tcp_matrix())

    def contact_wrench(self, flange: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Ground truth (tests and videos, never agents): the summed wrench of all the peg's
        contacts in the last physics step, world frame: force (N) and its moment (N m) about
        the flange (its pose `flange`, default the current one)."""
        origin = (self.flange_matrix() if flange is None else flange)[:3, 3]
        peg = self.agent.robot.links_map["peg"]._objs[0].entity
        return contact_wrench(self.scene, peg, origin, self.sim_freq)

    def wrist_wrench(self) -> np.ndarray:
        """What a 6-axis force/torque sensor between the flange and the peg reads: the
        contacts' wrench on the peg, in the flange frame about its origin, (fx, fy, fz, tx,
        ty, tz) in N and N m, with the sensor profile's bias (fixed per episode) and noise
        (one sample per control step, as a sensor polled at the control rate). The peg's
        own weight is tared out, as a real cell does before inserting. Nothing per contact
        is exposed: a real sensor sums them."""
        flange = self.flange_matrix()
        force, moment = self.contact_wrench(flange)
        R = flange[:3, :3]
        wrench = np.concatenate([R.T @ force, R.T @ moment])
        return wrench + self.sensing.wrench_error(int(self.elapsed_steps[0]))

    def ik(self, T: np.ndarray, seed: np.ndarray | None = None) -> tuple[np.ndarray, bool]:
        """Joint positions putting the tcp at world pose T (the robot base is the world),
        searched from `seed` (default: the arm's joints now)."""
        if seed is None:
            seed = self.agent.robot.get_qpos()[0].cpu().numpy()
        return self.kinematics.ik(T, seed)

    def insertion_pose(
        self, depth: float, hole: np.ndarray | None = None, ref: np.ndarray | None = None
    ):
        """Tcp pose with the tip `depth` m below the hole's opening (negative: above it).

        Tool z = -hole z. For a square hole the tool's x is the hole axis (x, y, -x, -y)
        nearest to `ref`'s x (the current tool), so the wrist never turns more than 45 deg.
        """
        H = self.hole_pose if hole is None else hole
        return insertion_pose(self.task.peg, H, depth, self.tcp_matrix() if ref is None else ref)

    # ------------------------------------------------------------------ episodes
    def _initialize_episode(self, env_idx: torch.Tensor, options: dict):
        cfg = self.task
        seed = int(self._batched_episode_rng[0].randint(0, 2**31 - 1))
        rng = np.random.default_rng(seed)
        self.wrist.start_episode(seed, self.scene.sensors, self.stereo)
        name = options.get("object")
        if name is not None:
            if name not in self.object_names:
                raise ValueError(
                    f"unknown object '{name}'; this env has: {', '.join(self.object_names)}"
                )
            idx = self.object_names.index(name)
        else:
            idx = int(rng.integers(len(self.object_names)))
        geom = self.geometries[idx]
        for _ in range(MAX_INIT_TRIES):
            T_obj, H = sample_object_pose(rng, cfg, geom)
            T_start = sample_start(rng, cfg, H, self.init_error_m)
            q0 = solvable_start(
                cfg, self.kinematics, self.collision, T_obj, H, T_start, self._surfaces[idx]
            )
            if q0 is not None:
                break
        else:
            raise RuntimeError(f"no reachable scene in {MAX_INIT_TRIES} tries for {geom.name}")
        for i, obj in enumerate(self.hole_objects):
            obj.set_pose(G.to_pose(T_obj) if i == idx else sapien.Pose(p=PARK + [0, i, 0]))
        self._show_only(idx)
        self.object_index = idx
        self._aim_cameras()
        self._init_error_m = float(np.linalg.norm(T_start[:3, 3] - H[:3, 3]))
        qt = torch.as_tensor(q0, dtype=torch.float32)[None]
        self.agent.reset(qt)
        self.episode_info = self._describe_episode()

    def _describe_episode(self) -> dict[str, Any]:
        H = self.hole_pose
        return dict(
            object=self.object_names[self.object_index],
            tilt_deg=float(np.degrees(np.arccos(np.clip(H[2, 2], -1, 1)))),
            init_error_m=self._init_error_m,
            hole_pose=H.tolist(),
        )

    @property
    def hole_pose(self) -> np.ndarray:
        """World pose of the current hole frame (origin: centre of the opening, +z out),
        from the active object's actor pose as PhysX holds it, so a restored state gives
        the same pose back to the last bit."""
        i = self.object_index
        T_obj = G.to_matrix(body_pose(self.hole_objects[i]))
        return T_obj @ G.make(np.eye(3), self.geometries[i].hole_frame)

    def object_surface(self) -> np.ndarray:
        """Ground truth (the oracle's planner, never agents): points on the active hole
        object's surface, world frame, about 1 cm apart."""
        T_obj = G.to_matrix(body_pose(self.hole_objects[self.object_index]))
        return self._surfaces[self.object_index] @ T_obj[:3, :3].T + T_obj[:3, 3]

    def _show_only(self, idx: int) -> None:
        """Render object idx only. Parked objects are out of view, but the renderer would
        still draw them every frame, so they leave the render scene."""
        for i, obj in enumerate(self.hole_objects):
            for body in obj._objs[0].get_components():
                if isinstance(body, sapien.render.RenderBodyComponent):
                    if i == idx and not body.is_enabled:
                        body.enable()
                    elif i != idx and body.is_enabled:
                        body.disable()

    def _active_object(self) -> int:
        """The hole object that is not parked (their poses are in the sim state)."""
        for i, obj in enumerate(self.hole_objects):
            if np.linalg.norm(obj.pose.sp.p - (PARK + [0, i, 0])) > 0.5:
                return i
        return self.object_index

    # ------------------------------------------------------------------ task state
    def get_state_dict(self):
        """ManiSkill's sim state plus the task's own (what BaseEnv asks tasks to add).

        The hole object's pose is an actor pose, so it is in the sim state already; which
        object is active follows from it (the others are parked). Added here: the depth
        noise stream's position (episode seed split into two exact 16-bit floats, and the
        number of observations drawn) and the start's distance for `episode_info`.
        """
        state = super().get_state_dict()
        state["task"] = task_state(self.wrist.seed, self.wrist.draws, self._init_error_m)
        return state

    def set_state_dict(self, state: dict, env_idx: torch.Tensor | None = None):
        super().set_state_dict(state, env_idx)
        task = state.get("task")
        if task is not None:
            seed, draws, self._init_error_m = read_task_state(task)
            self.wrist.seek(seed, draws)
            self.wrist.apply_episode_errors(self.scene.sensors, self.stereo)
        self.object_index = self._active_object()
        self._show_only(self.object_index)
        self._aim_cameras()
        self.episode_info = self._describe_episode()

    def set_state(self, state, env_idx: torch.Tensor | None = None):
        """The flat state back into get_state_dict()'s structure (ManiSkill's own set_state
        keeps only actors and articulations and would drop the task's part)."""
        state = torch.as_tensor(state)
        if state.ndim == 1:
            state = state[None]
        template = self.get_state_dict()
        self.set_state_dict(unflatten(state, template, self.task.env_id), env_idx)

    # ------------------------------------------------------------------ evaluation
    def evaluate(self) -> dict[str, torch.Tensor]:
        r = score(self.task, G.inv(self.hole_pose) @ self.tcp_matrix())
        # One tensor per kind, split into views: ManiSkill calls this every control step.
        flags = torch.tensor([[r["success"]], [not r["finite"]]], device=self.device)
        keys = (
            "tip_to_bottom",
            "lateral_offset",
            "tilt_error_deg",
            "tip_depth",
            "wall_penetration",
        )
        values = torch.tensor([[r[k]] for k in keys], dtype=torch.float32, device=self.device)
        return dict(success=flags[0], fail=flags[1], **{k: values[i] for i, k in enumerate(keys)})

    def _get_obs_extra(self, info: dict):
        extra = dict(tcp_pose=self.agent.tcp.pose.raw_pose)
        if self.obs_mode in ("state", "state_dict"):
            extra["hole_pose"] = torch.as_tensor(
                G.pose_vector(self.hole_pose), dtype=torch.float32
            )[None]
        return extra

    def get_obs(self, info: dict | None = None, unflattened: bool = False):
        if self.defer_obs:
            return {}
        obs = super().get_obs(info, unflattened)
        if not isinstance(obs, dict) or "sensor_param" not in obs:
            return obs
        return self.wrist.corrupt(obs)

    def compute_dense_reward(self, obs: Any, action: torch.Tensor, info: dict):
        # Distance of the tip to the hole's bottom plus the lateral offset, in metres.
        return -(info["tip_to_bottom"].abs() + info["lateral_offset"]) + 2.0 * info["success"]

    def compute_normalized_dense_reward(self, obs: Any, action: torch.Tensor, info: dict):
        return self.compute_dense_reward(obs, action, info) / 2.0
