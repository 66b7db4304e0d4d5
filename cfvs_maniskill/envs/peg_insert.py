"""The peg-in-hole task, parameterised by a task file and registered once per file."""

from __future__ import annotations

from typing import Any

import numpy as np
import sapien
import torch
from mani_skill.envs.sapien_env import BaseEnv
from mani_skill.sensors.camera import CameraConfig
from mani_skill.utils import sapien_utils
from mani_skill.utils.registration import register_env
from mani_skill.utils.structs.types import SceneConfig, SimConfig
from scipy.spatial.transform import Rotation

from cfvs_maniskill import geometry as G
from cfvs_maniskill.constants import (
    PRE_INSERT_HEIGHT,
    SUCCESS_LATERAL_MARGIN,
    SUCCESS_MAX_TILT_DEG,
    SUCCESS_TIP_TOLERANCE,
    hole_half_extent,
    peg_half_extent,
)
from cfvs_maniskill.envs.task_config import TaskConfig, load_task, load_tasks
from cfvs_maniskill.objects.build import build_geometry
from cfvs_maniskill.objects.library import load_library
from cfvs_maniskill.rendering import device
from cfvs_maniskill.robots.poses import flange_pose, insertion_pose
from cfvs_maniskill.robots.ur5 import (
    CAMERA_FOV,
    CAMERA_UID,
    STEREO_UIDS,
    TCP_LINK,
    TOOL_LINK,
    camera_pose_in_tool,
    robot_uid_for,
)
from cfvs_maniskill.sensing.depth import grid_points
from cfvs_maniskill.sensing.model import GL_TO_CV, SensorModel
from cfvs_maniskill.sensing.profile import load_profile

PARK = np.array([0.0, 5.0, -3.0])
"""Unused hole objects wait here, out of every camera's view."""
MAX_INIT_TRIES = 100
CLOSEUP_CAMERA = "closeup"
OVERVIEW_CAMERA = "overview"
CLOSEUP_PX = 512
CLOSEUP_FOV = 0.75
CLOSEUP_DISTANCE = 0.40
"""The close view: 512 px, 43 deg, 40 cm from the hole's opening (a 30 cm wide view: the
object's top, the peg and the last part of its approach)."""


def _cpu_pose(struct) -> sapien.Pose:
    """The pose of a ManiSkill Actor or Link straight from its SAPIEN object: the same
    float32 values as `struct.pose.sp` (which the CPU simulation reads from there too),
    without the round trip through batched tensors (50-70 us, paid several times per
    control step)."""
    if struct.scene.gpu_sim_enabled:
        return struct.pose.sp
    obj = struct._objs[0]
    return obj.entity_pose if hasattr(obj, "entity_pose") else obj.pose


def _quat_wxyz(T: np.ndarray) -> np.ndarray:
    p = G.to_pose(T)
    return np.concatenate([p.p, p.q])


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
    (agents/interface.py); the true hole pose in `state` is for the oracle and for training.
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
        **kwargs,
    ):
        if task_file is not None:  # this env's task is the file's, whatever the id's
            self.task = load_task(task_file)
        if self.task is None:
            raise ValueError(
                f"{GENERIC_ID} needs task_file=PATH (a task file like those in tasks/); "
                f"or make a registered task, e.g. PegInsert6DoF-v1"
            )
        cfg = self.task
        if stereo and "pointcloud" in str(kwargs.get("obs_mode", "")):
            raise ValueError(
                f"{cfg.env_id}: stereo=True adds the wrist camera's two stereo imagers for "
                "image agents; with obs_mode 'pointcloud' their points would be merged into "
                "the wrist cloud. Use an image obs mode (rgbd, rgb, rgb+depth)"
            )
        self.stereo = stereo
        """True: the wrist camera also delivers its stereo imagers' lit views (`STEREO_UIDS`;
        the right one the sensor profile's `imager.stereo_baseline` from the left)."""
        if num_envs != 1:
            raise ValueError(
                f"{cfg.env_id}: num_envs={num_envs} is not supported: the task's scene "
                "sampling, evaluation and observation noise are single-scene (numpy) code. "
                "Run many episodes in parallel with the evaluation's workers "
                "(`python -m cfvs_maniskill.eval --workers N`) or a vector of single envs "
                "(gymnasium.vector.AsyncVectorEnv of gym.make(..., num_envs=1))"
            )
        if isinstance(init_error, str):
            if init_error not in cfg.init_error:
                raise ValueError(
                    f"unknown init_error '{init_error}'; valid: {', '.join(cfg.init_error)} "
                    "or a distance in metres"
                )
            self.init_error_m = cfg.init_error[init_error]
        else:
            self.init_error_m = float(init_error)
        self.sensor_profile = load_profile(sensor)
        """The sensor profile (`sensors/<name>.yaml`): depth camera, hand-eye, wrench."""
        profile_std = self.sensor_profile.depth.std
        if depth_noise_std is not None:  # an explicit override wins
            self.depth_noise_std = depth_noise_std
        else:
            self.depth_noise_std = cfg.depth_noise_std if profile_std is None else profile_std
        self.sensing = SensorModel(self.sensor_profile, self.depth_noise_std)
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
        self._noise_gen = torch.Generator().manual_seed(0)
        self._noise_seed = 0
        self._noise_draws = 0
        """Observations that drew noise since the episode began: with `_noise_seed`, the
        noise stream's position, which the task state carries (see get_state_dict)."""
        self._noise_shapes: list[tuple[int, ...]] = []
        """Shapes one observation draws, in order (fixed per obs mode; learned on first use)."""
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
        # Tight-fit tasks use 0.2 mm, below their play per side, and switch PCM off
        # (TaskConfig.contact_offset and TaskConfig.pcm say why).
        return SimConfig(
            sim_freq=500,
            control_freq=20,
            scene_config=SceneConfig(
                contact_offset=self.task.contact_offset, enable_pcm=self.task.pcm
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
                pose=self._imager_pose(uid),
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

    def _imager_pose(self, uid: str, mount: sapien.Pose | None = None) -> sapien.Pose:
        """A stereo imager in tool0: the wrist camera's pose (nominal, or on the episode's
        miscalibrated `mount`), the right one moved by the baseline along the image x."""
        left = camera_pose_in_tool() * (mount or sapien.Pose())
        if uid == STEREO_UIDS[0]:
            return left
        return left * sapien.Pose(p=[0.0, -self.sensor_profile.imager.stereo_baseline, 0.0])

    @property
    def _default_human_render_camera_configs(self):
        # For people (videos, `render()`), never for agents: a close view that follows the
        # hole (aimed at every reset, `_aim_cameras`) and an overview of the arm, with
        # ManiSkill's lit "default" shader (the wrist camera keeps the fast "minimal" one).
        return [
            CameraConfig(
                CLOSEUP_CAMERA,
                pose=sapien.Pose(),
                width=CLOSEUP_PX,
                height=CLOSEUP_PX,
                fov=CLOSEUP_FOV,
                near=0.01,
                far=10,
                shader_pack="default",
            ),
            CameraConfig(
                OVERVIEW_CAMERA,
                pose=sapien.Pose(),
                width=CLOSEUP_PX // 2,
                height=CLOSEUP_PX // 2,
                fov=0.9,
                near=0.01,
                far=10,
                shader_pack="default",
            ),
        ]

    def _aim_cameras(self) -> None:
        """Aim the render cameras at this episode's hole. The close view looks at the
        opening from above, 55 deg off the hole's axis to the side (across the arm's
        approach, which would block it); the overview frames the arm's base and the hole
        from above that side, so the table, not the sky, is behind the arm."""
        H = self.hole_pose
        centre, z = H[:3, 3], H[:3, 2]
        out = centre - [0.0, 0.0, centre[2]]  # the base -> hole direction on the table
        side = np.cross([0.0, 0.0, 1.0], out)
        side = side / (np.linalg.norm(side) + 1e-9)
        look = np.cos(np.radians(55)) * z + np.sin(np.radians(55)) * side
        views = {
            CLOSEUP_CAMERA: (centre + CLOSEUP_DISTANCE * look, centre),
            OVERVIEW_CAMERA: (
                0.5 * centre + 0.75 * side + [0.0, 0.0, 0.8],
                0.6 * centre + [0.0, 0.0, 0.1],
            ),
        }
        for name, (eye, target) in views.items():
            cam = self._human_render_cameras.get(name)
            if cam is not None:  # None: the user replaced the render cameras
                cam.camera.set_local_pose(sapien_utils.look_at(eye=eye, target=target).sp)

    def _load_agent(self, options: dict):
        super()._load_agent(options, sapien.Pose())
        self.agent.camera_width = self.task.camera_width
        self.agent.camera_height = self.task.camera_height

    def _load_scene(self, options: dict):
        b = self.scene.create_actor_builder()
        b.add_box_collision(half_size=[1.0, 1.0, 0.025])
        b.add_box_visual(
            half_size=[1.0, 1.0, 0.025],
            material=sapien.render.RenderMaterial(base_color=[0.82, 0.8, 0.76, 1.0]),
        )
        b.initial_pose = sapien.Pose(p=[0.3, 0, -0.025])
        self.table = b.build_static(name="table")
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
        robot = self.agent.robot._objs[0]
        self._pin = robot.create_pinocchio_model()
        # Pinocchio numbers links as the articulation does; ManiSkill prefixes their names.
        limits = self.agent.robot.get_qlimits()[0].cpu().numpy()
        self._qlimits = (limits[:, 0], limits[:, 1])
        names = [link.name for link in robot.get_links()]
        self._tcp_index = next(i for i, n in enumerate(names) if n.endswith(TCP_LINK))

    # ------------------------------------------------------------------ kinematics
    def tcp_matrix(self) -> np.ndarray:
        """True world pose of the peg tip frame (z along the peg, out of the flange)."""
        return G.to_matrix(_cpu_pose(self.agent.tcp))

    def flange_matrix(self) -> np.ndarray:
        """True world pose of the flange (tool0): the tcp frame PEG_LENGTH back along z."""
        return flange_pose(self.tcp_matrix())

    def contact_wrench(self, flange: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Ground truth (tests and videos, never agents): the summed wrench of all the peg's
        contacts in the last physics step, world frame: force (N) and its moment (N m) about
        the flange (its pose `flange`, default the current one)."""
        origin = (self.flange_matrix() if flange is None else flange)[:3, 3]
        force, moment = np.zeros(3), np.zeros(3)
        peg = self.agent.robot.links_map["peg"]._objs[0].entity
        rate = self.sim_freq  # PhysX reports impulses over one physics step
        for c in self.scene.px.get_contacts():
            sign = 1.0 if c.bodies[0].entity == peg else -1.0 if c.bodies[1].entity == peg else 0
            if sign == 0:
                continue
            for point in c.points:  # the impulse acts on the contact's first body
                f = sign * rate * np.asarray(point.impulse, np.float64)
                force += f
                moment += np.cross(np.asarray(point.position, np.float64) - origin, f)
        return force, moment

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
        """Joint positions putting the tcp at world pose T (the robot base is the world)."""
        if seed is None:
            seed = self.agent.robot.get_qpos()[0].cpu().numpy()
        if not np.all(np.isfinite(T)):
            return seed, False
        q, ok, _ = self._pin.compute_inverse_kinematics(
            self._tcp_index,
            G.to_pose(T),
            initial_qpos=np.asarray(seed, np.float64),
            max_iterations=300,
        )
        if ok:
            # Pinocchio ignores joint limits; bring angles into them by whole turns, or fail.
            lo, hi = self._qlimits
            q = np.where(q > hi, q - 2 * np.pi, np.where(q < lo, q + 2 * np.pi, q))
            ok = bool(np.all((q >= lo) & (q <= hi)))
        if ok:
            self._pin.compute_forward_kinematics(q)
            got = G.to_matrix(self._pin.get_link_pose(self._tcp_index))
            ok = (
                np.linalg.norm(got[:3, 3] - T[:3, 3]) < 1e-3
                and G.rot_angle(got[:3, :3].T @ T[:3, :3]) < 1e-2
            )
        return np.asarray(q), bool(ok)

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
        self._noise_gen.manual_seed(seed)
        self._noise_seed, self._noise_draws = seed, 0
        self._start_sensing(seed)
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
        home = np.asarray(self.agent.keyframes["home"].qpos)
        for _ in range(MAX_INIT_TRIES):
            T_obj, H = self._sample_object_pose(rng, geom)
            T_start = self._sample_start(rng, H)
            q0, ok0 = self.ik(T_start, home)
            q1, ok1 = self.ik(self.insertion_pose(-PRE_INSERT_HEIGHT, H, T_start), q0)
            _, ok2 = self.ik(self.insertion_pose(cfg.hole_depth - 0.002, H, T_start), q1)
            if ok0 and ok1 and ok2:
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
        T_obj = G.to_matrix(_cpu_pose(self.hole_objects[i]))
        return T_obj @ G.make(np.eye(3), self.geometries[i].hole_frame)

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
        seed = self._noise_seed
        state["task"] = dict(
            noise=torch.tensor(
                [[seed >> 16, seed & 0xFFFF, self._noise_draws]], dtype=torch.float32
            ),
            init_error=torch.tensor([[self._init_error_m]], dtype=torch.float32),
        )
        return state

    def set_state_dict(self, state: dict, env_idx: torch.Tensor | None = None):
        super().set_state_dict(state, env_idx)
        task = state.get("task")
        if task is not None:
            hi, lo, draws = (int(round(float(x))) for x in np.asarray(task["noise"]).reshape(-1))
            self._seek_noise((hi << 16) | lo, draws)
            self._start_sensing(self._noise_seed)
            self._init_error_m = float(np.asarray(task["init_error"]).reshape(-1)[0])
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

        def unflatten(template: dict, start: int) -> tuple[dict, int]:
            out = {}
            for k, v in template.items():
                if isinstance(v, dict):
                    out[k], start = unflatten(v, start)
                    continue
                n = v.shape[-1] if v.ndim > 1 else 1
                out[k] = state[:, start : start + n]
                start += n
            return out, start

        state_dict, used = unflatten(self.get_state_dict(), 0)
        if used != state.shape[-1]:
            raise ValueError(
                f"{self.task.env_id}: a flat state of {state.shape[-1]} values, expected "
                f"{used} (get_state()'s length for this env)"
            )
        self.set_state_dict(state_dict, env_idx)

    def _start_sensing(self, seed: int) -> None:
        """Draw the episode's sensor errors and put the camera where its (mis)calibrated
        mount really holds it: images come from the true camera, while the cloud is placed
        in the world with the nominal mount, as a robot that trusts its calibration does."""
        self.sensing.start_episode(seed)
        mount = G.to_pose(self.sensing.mount)
        self.scene.sensors[CAMERA_UID].camera.set_local_pose(camera_pose_in_tool() * mount)
        if self.stereo:  # one rigid camera body: the imagers share the mount's error
            for uid in STEREO_UIDS:
                self.scene.sensors[uid].camera.set_local_pose(self._imager_pose(uid, mount))

    def _seek_noise(self, seed: int, draws: int) -> None:
        """Put the noise stream where it was after `draws` noisy observations of the
        episode seeded `seed` (forward from here when that is ahead, else from its start)."""
        if seed != self._noise_seed or draws < self._noise_draws:
            self._noise_gen.manual_seed(seed)
            self._noise_seed, self._noise_draws = seed, 0
        for _ in range(draws - self._noise_draws):
            for shape in self._noise_shapes:
                torch.randn(shape, generator=self._noise_gen)
        self._noise_draws = draws

    def _sample_object_pose(self, rng: np.random.Generator, geom) -> tuple[np.ndarray, np.ndarray]:
        cfg = self.task
        yaw = np.radians(rng.uniform(*cfg.yaw_deg))
        tilt = np.radians(rng.uniform(*cfg.tilt_deg))
        azimuth = rng.uniform(0, 2 * np.pi)
        axis = np.array([np.cos(azimuth), np.sin(azimuth), 0.0])
        R = (Rotation.from_rotvec(axis * tilt) * Rotation.from_euler("z", yaw)).as_matrix()
        v = geom.visual_vertices @ R.T
        xy = [rng.uniform(*cfg.workspace_x), rng.uniform(*cfg.workspace_y)]
        # Place the body so that its lowest point touches the table.
        T_obj = G.make(R, np.array([*xy, -v[:, 2].min()]))
        H = T_obj @ G.make(np.eye(3), geom.hole_frame)
        return T_obj, H

    def _sample_start(self, rng: np.random.Generator, H: np.ndarray) -> np.ndarray:
        cfg = self.task
        while True:
            u = G.random_cone(rng, H[:3, 2], np.radians(cfg.init_cone_deg))
            if u[2] > 0.5:  # start above the hole, never below the table's horizon
                break
        p = H[:3, 3] + self.init_error_m * u
        look = G.random_cone(rng, -u, np.radians(cfg.init_aim_deg))
        R = G.frame_with_z(look, np.array([1.0, 0.0, 0.0]))
        roll = np.radians(rng.uniform(-cfg.init_roll_deg, cfg.init_roll_deg))
        c, s = np.cos(roll), np.sin(roll)
        R = R @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        return G.make(R, p)

    # ------------------------------------------------------------------ evaluation
    def evaluate(self) -> dict[str, torch.Tensor]:
        cfg = self.task
        T = G.inv(self.hole_pose) @ self.tcp_matrix()
        tip = T[:3, 3]
        lateral = float(np.hypot(tip[0], tip[1]))
        tip_to_bottom = float(tip[2] + cfg.hole_depth)
        tilt = float(np.degrees(np.arccos(np.clip(-T[2, 2], -1, 1))))
        room = hole_half_extent(cfg.peg, cfg.clearance) - peg_half_extent(cfg.peg)
        inside = (
            lateral <= room * np.sqrt(2) + SUCCESS_LATERAL_MARGIN
            and max(abs(tip[0]), abs(tip[1])) <= room + SUCCESS_LATERAL_MARGIN
        )
        success = (
            abs(tip_to_bottom) <= SUCCESS_TIP_TOLERANCE and inside and tilt <= SUCCESS_MAX_TILT_DEG
        )
        finite = bool(np.all(np.isfinite(T)))
        # One tensor per kind, split into views: ManiSkill calls this every control step.
        flags = torch.tensor([[success and finite], [not finite]], device=self.device)
        values = torch.tensor(
            [[tip_to_bottom], [lateral], [tilt], [-tip[2]]], dtype=torch.float32, device=self.device
        )
        return dict(
            success=flags[0],
            fail=flags[1],
            tip_to_bottom=values[0],
            lateral_offset=values[1],
            tilt_error_deg=values[2],
            tip_depth=values[3],
        )

    def _get_obs_extra(self, info: dict):
        extra = dict(tcp_pose=self.agent.tcp.pose.raw_pose)
        if self.obs_mode in ("state", "state_dict"):
            extra["hole_pose"] = torch.as_tensor(_quat_wxyz(self.hole_pose), dtype=torch.float32)[
                None
            ]
        return extra

    def get_obs(self, info: dict | None = None, unflattened: bool = False):
        if self.defer_obs:
            return {}
        obs = super().get_obs(info, unflattened)
        if not isinstance(obs, dict) or "sensor_param" not in obs:
            return obs
        if not self.sensing.is_iid:
            return self._stereo_obs(obs)
        self._misreport_camera(obs)
        std = self.depth_noise_std
        if std > 0:
            shapes = []

            def randn(shape) -> torch.Tensor:
                shapes.append(tuple(shape))
                return torch.randn(shape, generator=self._noise_gen)

            if "pointcloud" in obs:
                xyzw = obs["pointcloud"]["xyzw"]
                noise = randn(xyzw[..., :3].shape) * std
                xyzw[..., :3] += noise.to(xyzw.device) * (xyzw[..., 3:] > 0)
            for cam in obs.get("sensor_data", {}).values():
                if "depth" in cam:  # int16 millimetres
                    d = cam["depth"]
                    noise = randn(d.shape) * std * 1000
                    cam["depth"] = torch.where(d > 0, (d + noise.round().to(d.dtype)), d)
            if shapes:
                self._noise_shapes = shapes
                self._noise_draws += 1
        return obs

    def _true_camera(self, obs: dict) -> dict[str, np.ndarray]:
        """The wrist camera's true parameters, as the renderer placed it (in the observation
        until `_misreport_camera` replaces them)."""
        params = obs["sensor_param"][CAMERA_UID]
        return {k: v[0].cpu().numpy().astype(np.float64) for k, v in params.items()}

    def _misreport_camera(self, obs: dict, true_cam: dict | None = None, cloud: bool = True):
        """With a hand-eye error, the cloud is placed with the believed (nominal) camera
        pose, and the sensor parameters say that pose."""
        if np.array_equal(self.sensing.mount, np.eye(4)):
            return
        true_cam = true_cam or self._true_camera(obs)
        T_true = true_cam["cam2world_gl"]
        T_rep = self.sensing.reported_cam2world_gl(T_true)
        if cloud and "pointcloud" in obs:
            M = torch.as_tensor(T_rep @ G.inv(T_true), dtype=torch.float32)
            xyzw = obs["pointcloud"]["xyzw"]
            xyzw[..., :3] = xyzw[..., :3] @ M[:3, :3].T.to(xyzw.device) + M[:3, 3].to(xyzw.device)
        param = obs["sensor_param"].get(CAMERA_UID)
        if param is not None:
            param["cam2world_gl"] = torch.as_tensor(T_rep, dtype=torch.float32)[None]
            ext = G.inv(T_rep @ GL_TO_CV)[:3]
            param["extrinsic_cv"] = torch.as_tensor(ext, dtype=torch.float32)[None]

    def _stereo_obs(self, obs: dict) -> dict:
        """The profile's stereo depth model on the wrist camera's cloud or depth image."""
        cam = self._true_camera(obs)
        draw = self._noise_draws
        h, w = self.task.camera_height, self.task.camera_width
        if "pointcloud" in obs:
            xyzw = obs["pointcloud"]["xyzw"]
            x = xyzw[0].cpu().numpy().reshape(h, w, 4)
            T = cam["cam2world_gl"].astype(np.float32)
            local = (x[..., :3] - T[:3, 3]) @ T[:3, :3]  # world -> camera (OpenGL axes)
            pts, ok = self.sensing.stereo_points_gl(local, x[..., 3] > 0, draw, cam["intrinsic_cv"])
            # Back to the world through the pose the robot believes the camera has.
            B = self.sensing.reported_cam2world_gl(cam["cam2world_gl"]).astype(np.float32)
            world = pts @ B[:3, :3].T + B[:3, 3]
            world[~ok] = 0.0
            out = np.concatenate([world, ok[..., None]], axis=-1)
            obs["pointcloud"]["xyzw"] = torch.as_tensor(
                out.reshape(1, h * w, 4), dtype=xyzw.dtype, device=xyzw.device
            )
        for name, data in obs.get("sensor_data", {}).items():
            if name == CAMERA_UID and "depth" in data:  # int16 millimetres
                d = data["depth"]
                z = d[0, ..., 0].cpu().numpy().astype(np.float32) / 1000.0
                pts = grid_points(z, cam["intrinsic_cv"])
                new, ok = self.sensing.stereo_points_cv(pts, z > 0, draw, cam["intrinsic_cv"])
                mm = np.where(ok, np.round(new[..., 2] * 1000.0), 0.0)
                data["depth"] = torch.as_tensor(mm, dtype=d.dtype, device=d.device)[None, ..., None]
        self._misreport_camera(obs, cam, cloud=False)  # the cloud is placed already
        self._noise_draws += 1
        return obs

    def compute_dense_reward(self, obs: Any, action: torch.Tensor, info: dict):
        # Distance of the tip to the hole's bottom plus the lateral offset, in metres.
        return -(info["tip_to_bottom"].abs() + info["lateral_offset"]) + 2.0 * info["success"]

    def compute_normalized_dense_reward(self, obs: Any, action: torch.Tensor, info: dict):
        return self.compute_dense_reward(obs, action, info) / 2.0


GENERIC_ID = "PegInsert-v1"
"""The task of any task file: `gym.make(GENERIC_ID, task_file=PATH)`."""


def register_tasks() -> dict[str, TaskConfig]:
    """Register `<name>-v1` for every bundled task file and every one in the user folder,
    and GENERIC_ID for a task file given by path (idempotent)."""
    from mani_skill.utils.registration import REGISTERED_ENVS

    if GENERIC_ID not in REGISTERED_ENVS:
        cls = type("PegInsert", (PegInsertEnv,), {"__doc__": PegInsertEnv.__doc__})
        register_env(GENERIC_ID, max_episode_steps=None)(cls)
    tasks = load_tasks()
    for name, cfg in tasks.items():
        if cfg.env_id in REGISTERED_ENVS:
            continue
        cls = type(name, (PegInsertEnv,), {"task": cfg, "__doc__": PegInsertEnv.__doc__})
        register_env(cfg.env_id, max_episode_steps=cfg.max_episode_steps)(cls)
    return tasks


__all__ = ["GENERIC_ID", "PegInsertEnv", "register_tasks"]
