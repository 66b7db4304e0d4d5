"""The sensor profile applied to what the wrist camera delivers: where the (miscalibrated)
camera really sits, its depth errors on the cloud or depth image, and the camera pose the
robot believes. The env hands every observation through `WristSensing.corrupt`."""

from __future__ import annotations

import numpy as np
import sapien
import torch

from cfvs_maniskill import geometry as G
from cfvs_maniskill.robots.ur5 import CAMERA_FOV, CAMERA_UID, STEREO_UIDS, camera_pose_in_tool
from cfvs_maniskill.sensing import surfaces
from cfvs_maniskill.sensing.depth import grid_points
from cfvs_maniskill.sensing.model import GL_TO_CV, SensorModel
from cfvs_maniskill.sensing.profile import SensorProfile


def camera_geometry(task, profile: SensorProfile) -> tuple[int, int, float]:
    """(width, height, vertical fov in rad) of the rendered wrist camera: the task's size
    (`camera_width`, `camera_height`) at its 70 deg field of view, or the profile's field of
    view at the same angular resolution (square pixels), so a wider camera sees more rather
    than coarser."""
    width, height = task.camera_width, task.camera_height
    fov = profile.depth.fov_deg
    if fov is None:
        return width, height, float(CAMERA_FOV)
    focal = (height / 2) / np.tan(CAMERA_FOV / 2)
    h_rad, v_rad = np.radians(fov[0]), np.radians(fov[1])
    w = int(round(2 * focal * np.tan(h_rad / 2)))
    h = int(round(2 * focal * np.tan(v_rad / 2)))
    return w, h, float(2 * np.arctan((h / 2) / focal))


class WristSensing:
    def __init__(self, model: SensorModel, iid_std: float, width: int, height: int):
        self.model = model
        self.nominal = camera_pose_in_tool(model.profile.camera_mount)
        """The camera's pose in tool0 on the profile's mount, as drawn (no error)."""
        self.iid_std = iid_std
        """Per-point depth noise of an iid model, m."""
        self.width, self.height = width, height
        self.generator = torch.Generator().manual_seed(0)
        self.seed = 0
        self.draws = 0
        """Observations that drew noise since the episode began: with `seed`, the noise
        stream's position, which the task state carries."""
        self.shapes: list[tuple[int, ...]] = []
        """Shapes one observation draws, in order (fixed per obs mode; learned on first use)."""
        self.contrast_lut = np.zeros(1, dtype=np.float32)
        """Texture contrast per segmentation id (`learn_surfaces`)."""
        self.camera = None
        """The wrist camera (for its colour and segmentation when the obs lacks them)."""

    def learn_surfaces(self, table, robot, parts: list, specs: list) -> None:
        """Each scene entity's texture contrast by segmentation id: the table's, the arm's,
        the peg's, and each hole object's (`parts`, with their `specs`; the profile's
        `surfaces.part_material` overrides their files)."""
        override = self.model.profile.surfaces.part_material
        by_id = {int(table.per_scene_id[0]): surfaces.MATERIALS[surfaces.TABLE_MATERIAL]}
        for link in robot.links:
            material = surfaces.PEG_MATERIAL if link.name == "peg" else surfaces.ROBOT_MATERIAL
            by_id[int(link.per_scene_id[0])] = surfaces.MATERIALS[material]
        for actor, spec in zip(parts, specs, strict=True):
            c = spec.texture_contrast if override is None else surfaces.MATERIALS[override]
            by_id[int(actor.per_scene_id[0])] = c
        self.contrast_lut = surfaces.lookup_table(by_id)

    def _surface(self, obs: dict) -> tuple[np.ndarray, np.ndarray] | None:
        """(albedo, texture contrast) per wrist-camera pixel, from the rendered flat colour
        and the segmentation; None when the profile ignores texture."""
        if self.model.profile.depth.imager_noise <= 0:
            return None
        h, w = self.height, self.width
        pc = obs.get("pointcloud", {})
        if "rgb" in pc and "segmentation" in pc:
            rgb, seg = pc["rgb"], pc["segmentation"]
        else:
            images = self.camera.get_obs(rgb=True, depth=False, position=False, segmentation=True)
            rgb, seg = images["rgb"], images["segmentation"]
        rgb = rgb[0].cpu().numpy().reshape(h, w, 3).astype(np.float32) / 255.0
        ids = seg[0].cpu().numpy().reshape(h, w).astype(np.int64)
        ids = np.where(ids < len(self.contrast_lut), ids, 0)
        return rgb @ surfaces.GREY, self.contrast_lut[ids]

    def imager_pose(self, uid: str, mount: sapien.Pose | None = None) -> sapien.Pose:
        """A stereo imager in tool0: the wrist camera's pose (nominal, or on the episode's
        miscalibrated `mount`), the right one moved by the baseline along the image x."""
        left = self.nominal * (mount or sapien.Pose())
        if uid == STEREO_UIDS[0]:
            return left
        return left * sapien.Pose(p=[0.0, -self.model.profile.imager.stereo_baseline, 0.0])

    def start_episode(self, seed: int, sensors: dict, stereo: bool) -> None:
        """A new episode's noise stream and errors; the camera goes where its miscalibrated
        mount really holds it: images come from the true camera, while the cloud is placed
        in the world with the nominal mount, as a robot that trusts its calibration does."""
        self.generator.manual_seed(seed)
        self.seed, self.draws = seed, 0
        self.camera = sensors[CAMERA_UID]
        self.apply_episode_errors(sensors, stereo)

    def apply_episode_errors(self, sensors: dict, stereo: bool) -> None:
        """Draw the episode's sensor errors (from `seed`) and put the cameras on the
        miscalibrated mount; a restored state calls this after `seek`."""
        self.model.start_episode(self.seed)
        mount = G.to_pose(self.model.mount)
        sensors[CAMERA_UID].camera.set_local_pose(self.nominal * mount)
        if stereo:  # one rigid camera body: the imagers share the mount's error
            for uid in STEREO_UIDS:
                sensors[uid].camera.set_local_pose(self.imager_pose(uid, mount))

    def seek(self, seed: int, draws: int) -> None:
        """Put the noise stream where it was after `draws` noisy observations of the
        episode seeded `seed` (forward from here when that is ahead, else from its start)."""
        if seed != self.seed or draws < self.draws:
            self.generator.manual_seed(seed)
            self.seed, self.draws = seed, 0
        for _ in range(draws - self.draws):
            for shape in self.shapes:
                torch.randn(shape, generator=self.generator)
        self.draws = draws

    def corrupt(self, obs: dict) -> dict:
        """The observation as the profile's camera delivers it (changed in place)."""
        if "pointcloud" in obs:
            self._unbias_render(obs)
        if not self.model.is_iid:
            return self._stereo(obs)
        self._misreport_camera(obs)
        if self.iid_std <= 0:
            return obs
        shapes = []

        def randn(shape) -> torch.Tensor:
            shapes.append(tuple(shape))
            return torch.randn(shape, generator=self.generator)

        if "pointcloud" in obs:
            xyzw = obs["pointcloud"]["xyzw"]
            noise = randn(xyzw[..., :3].shape) * self.iid_std
            xyzw[..., :3] += noise.to(xyzw.device) * (xyzw[..., 3:] > 0)
        for cam in obs.get("sensor_data", {}).values():
            if "depth" in cam:  # int16 millimetres
                d = cam["depth"]
                noise = randn(d.shape) * self.iid_std * 1000
                cam["depth"] = torch.where(d > 0, (d + noise.round().to(d.dtype)), d)
        if shapes:
            self.shapes = shapes
            self.draws += 1
        return obs

    def _unbias_render(self, obs: dict) -> None:
        """The renderer writes camera-space positions in whole millimetres, truncated toward
        zero (SAPIEN's minimal shader: `ivec3(position * 1000)`): every surface comes up to
        1 mm nearer the camera, 0.5 mm on average. Each point goes to the middle of its
        millimetre, leaving an unbiased +-0.5 mm quantisation."""
        T = torch.as_tensor(self._true_camera(obs)["cam2world_gl"])
        xyzw = obs["pointcloud"]["xyzw"]
        R, t = T[:3, :3].to(xyzw.device), T[:3, 3].to(xyzw.device)
        local = (xyzw[..., :3].double() - t) @ R  # world -> camera (OpenGL axes), metres
        local += 0.0005 * torch.sign(torch.round(local * 1000.0))
        xyzw[..., :3] = (local @ R.T + t).to(xyzw.dtype)

    @staticmethod
    def _true_camera(obs: dict) -> dict[str, np.ndarray]:
        """The wrist camera's true parameters, as the renderer placed it (in the observation
        until `_misreport_camera` replaces them)."""
        params = obs["sensor_param"][CAMERA_UID]
        return {k: v[0].cpu().numpy().astype(np.float64) for k, v in params.items()}

    def _misreport_camera(self, obs: dict, true_cam: dict | None = None, cloud: bool = True):
        """With a hand-eye error, the cloud is placed with the believed (nominal) camera
        pose, and the sensor parameters say that pose (and the reported intrinsics)."""
        calibrated = np.array_equal(self.model.mount, np.eye(4))
        if calibrated and not self.model.depth_errors.intrinsics_off:
            return
        true_cam = true_cam or self._true_camera(obs)
        param = obs["sensor_param"].get(CAMERA_UID)
        if param is not None and "intrinsic_cv" in param:
            K = self.model.reported_intrinsic(true_cam["intrinsic_cv"])
            param["intrinsic_cv"] = torch.as_tensor(K, dtype=torch.float32)[None]
        if calibrated:
            return
        T_true = true_cam["cam2world_gl"]
        T_rep = self.model.reported_cam2world_gl(T_true)
        if cloud and "pointcloud" in obs:
            M = torch.as_tensor(T_rep @ G.inv(T_true), dtype=torch.float32)
            xyzw = obs["pointcloud"]["xyzw"]
            xyzw[..., :3] = xyzw[..., :3] @ M[:3, :3].T.to(xyzw.device) + M[:3, 3].to(xyzw.device)
        if param is not None:
            param["cam2world_gl"] = torch.as_tensor(T_rep, dtype=torch.float32)[None]
            ext = G.inv(T_rep @ GL_TO_CV)[:3]
            param["extrinsic_cv"] = torch.as_tensor(ext, dtype=torch.float32)[None]

    def _stereo(self, obs: dict) -> dict:
        """The profile's stereo depth model on the wrist camera's cloud or depth image."""
        cam = self._true_camera(obs)
        h, w = self.height, self.width
        surface = self._surface(obs)
        if "pointcloud" in obs:
            xyzw = obs["pointcloud"]["xyzw"]
            x = xyzw[0].cpu().numpy().reshape(h, w, 4)
            T = cam["cam2world_gl"].astype(np.float32)
            local = (x[..., :3] - T[:3, 3]) @ T[:3, :3]  # world -> camera (OpenGL axes)
            pts, ok = self.model.stereo_points_gl(
                local, x[..., 3] > 0, self.draws, cam["intrinsic_cv"], surface
            )
            # Back to the world through the pose the robot believes the camera has.
            B = self.model.reported_cam2world_gl(cam["cam2world_gl"]).astype(np.float32)
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
                new, ok = self.model.stereo_points_cv(
                    pts, z > 0, self.draws, cam["intrinsic_cv"], surface
                )
                mm = np.where(ok, np.round(new[..., 2] * 1000.0), 0.0)
                data["depth"] = torch.as_tensor(mm, dtype=d.dtype, device=d.device)[None, ..., None]
        self._misreport_camera(obs, cam, cloud=False)  # the cloud is placed already
        self.draws += 1
        return obs
