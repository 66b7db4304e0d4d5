"""UR5 with a peg rigidly on its flange (no gripper) and an eye-in-hand RGB-D camera.

The arm comes from the PyPI package `example-robot-data` (BSD); nothing is downloaded. When
an env is first made (never at import) we write a derived URDF into the cache folder:
  * mesh paths made absolute; the low-poly collision STLs also serve as visual meshes,
    because rendering cost is set by the triangles in view (the .dae visuals are ~50x more);
  * the stock 1 cm `ee_link` collision box removed (it would touch the peg);
  * `tool0` (already in the URDF): the flange frame, +z along the tool axis;
  * `peg`: a 100 mm round or square peg along tool0's +z (sizes from `constants`), its tip
    edges optionally chamfered at 45 deg (tight-fit tasks; a convex mesh written beside the
    URDF, which PhysX uses as one convex hull);
  * `tcp`: the peg's tip, same axes as tool0. Poses the executor commands are tcp poses.

Self-collision: every link pair of the arm is filtered (ManiSkill's `disable_self_collisions`),
so the peg never collides with the wrist it is bolted to; the arm and peg still collide with
the world. The executor's moves stay in the open workspace above the table.

Joint drives: stiffness 2000 N m/rad, damping 200 N m s/rad, torque limits from the UR5
datasheet (150 N m shoulder/elbow, 28 N m wrist). Gravity is compensated by ManiSkill
(`balance_passive_force`), so the stiffness only resists contact: a 5 mm lead at 0.5 m gives
tens of newtons at the tip, never kilonewtons.
"""

from __future__ import annotations

import hashlib
import os
import xml.etree.ElementTree as ET
from copy import deepcopy
from pathlib import Path

import numpy as np
import sapien
from mani_skill.agents.base_agent import BaseAgent, Keyframe
from mani_skill.agents.controllers import (
    PDJointPosControllerConfig,
    PDJointPosVelControllerConfig,
    deepcopy_dict,
)
from mani_skill.agents.registration import REGISTERED_AGENTS, register_agent
from mani_skill.sensors.camera import CameraConfig

from cfvs_maniskill import geometry as G
from cfvs_maniskill import resources
from cfvs_maniskill.constants import PEG_LENGTH, ROUND_PEG_RADIUS, SQUARE_PEG_SIDE
from cfvs_maniskill.robots.mounts import DEFAULT_MOUNT, MOUNTS, Mount
from cfvs_maniskill.robots.peg import chamfered_peg_mesh

ARM_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
TORQUE_LIMITS = np.array([150.0, 150.0, 150.0, 28.0, 28.0, 28.0])
"""N m, from the UR5 datasheet (the URDF's `effort` values)."""
STIFFNESS = 2000.0
DAMPING = 200.0

HOME_QPOS = np.array([0.0, -1.9, 1.9, -1.571, -1.571, 0.0])


def start_seeds(T: np.ndarray) -> list[np.ndarray]:
    """IK starts for a tcp pose T, in order: the home pose, then home turned to face T
    with the elbow up (the first can converge to an elbow-down branch whose upper arm
    dips into the table)."""
    pan = np.arctan2(T[1, 3], T[0, 3])
    return [HOME_QPOS, HOME_QPOS + [pan, 0, 0, 0, 0, 0], HOME_QPOS + [pan, 0.4, -0.4, 0, 0, 0]]


"""Peg pointing straight down about 0.35 m above the table, 0.45 m in front of the base."""

TCP_LINK = "tcp"
TOOL_LINK = "tool0"
CAMERA_UID = "wrist_camera"
STEREO_UIDS = ("wrist_left", "wrist_right")
"""The wrist camera's two stereo imagers (envs made with stereo=True; image agents, KOVIS)."""
CAMERA_FOV = np.deg2rad(70.0)
"""Vertical field of view, radians."""


def _ur5_dir() -> Path:
    from importlib import metadata

    try:  # wherever the distribution is installed: a venv, the user site, a path
        dist = metadata.distribution("example-robot-data")
        d = Path(str(dist.locate_file("cmeel.prefix/share/example-robot-data/robots")))
        if (d / "ur_description").is_dir():
            return d / "ur_description"
    except metadata.PackageNotFoundError:
        pass
    raise FileNotFoundError(
        "example-robot-data's ur_description not found in site-packages; "
        "run `pip install example-robot-data==6.0.0`"
    )


def camera_pose_in_tool(mount: Mount | None = None) -> sapien.Pose:
    """Pose of the wrist camera in tool0 on `mount` (default: DEFAULT_MOUNT's); SAPIEN
    cameras look along their +x."""
    return G.to_pose((mount or MOUNTS[DEFAULT_MOUNT]).in_tool())


def _link(name: str, geometry: ET.Element | None, z_center: float, mass: float) -> ET.Element:
    link = ET.Element("link", name=name)
    inertial = ET.SubElement(link, "inertial")
    ET.SubElement(inertial, "mass", value=f"{mass}")
    ET.SubElement(inertial, "origin", xyz=f"0 0 {z_center}", rpy="0 0 0")
    ET.SubElement(
        inertial, "inertia", ixx="1e-4", iyy="1e-4", izz="1e-4", ixy="0", ixz="0", iyz="0"
    )
    if geometry is not None:
        for tag in ("visual", "collision"):
            el = ET.SubElement(link, tag)
            ET.SubElement(el, "origin", xyz=f"0 0 {z_center}", rpy="0 0 0")
            el.append(deepcopy(geometry))
    return link


def _fixed(name: str, parent: str, child: str, xyz: str, rpy: str) -> ET.Element:
    j = ET.Element("joint", name=name, type="fixed")
    ET.SubElement(j, "parent", link=parent)
    ET.SubElement(j, "child", link=child)
    ET.SubElement(j, "origin", xyz=xyz, rpy=rpy)
    return j


def build_urdf(profile: str, chamfer: float = 0.0, mesh_file: str = "") -> str:
    """Text of the UR5 + peg URDF for a peg `profile` ("round" or "square"); with `chamfer`
    > 0 the peg is the convex mesh at `mesh_file` (see `chamfered_peg_mesh`)."""
    src = _ur5_dir()
    tree = ET.parse(src / "urdf" / "ur5_robot.urdf")
    robot = tree.getroot()
    for el in list(robot):
        if el.tag in ("gazebo", "transmission"):
            robot.remove(el)
    for link in robot.findall("link"):
        if link.get("name") == "ee_link":
            for c in link.findall("collision"):
                link.remove(c)
        for vis in link.findall("visual"):
            mesh = vis.find("geometry/mesh")
            if mesh is not None:
                mesh.set(
                    "filename",
                    mesh.get("filename").replace("/visual/", "/collision/").replace(".dae", ".stl"),
                )
    for mesh in robot.iter("mesh"):
        fn = mesh.get("filename")
        mesh.set("filename", str(src / fn.split("ur_description/", 1)[1]))

    geom = ET.Element("geometry")
    peg_z = PEG_LENGTH / 2
    if chamfer > 0:
        ET.SubElement(geom, "mesh", filename=mesh_file)
        peg_z = 0.0  # the mesh is already in tool0 coordinates
    elif profile == "round":
        ET.SubElement(geom, "cylinder", radius=f"{ROUND_PEG_RADIUS}", length=f"{PEG_LENGTH}")
    else:
        s = SQUARE_PEG_SIDE
        ET.SubElement(geom, "box", size=f"{s} {s} {PEG_LENGTH}")
    # The URDF's own tool0 is the flange frame with +z out of the flange (ROS-I convention).
    robot.append(_fixed("peg_joint", TOOL_LINK, "peg", "0 0 0", "0 0 0"))
    robot.append(_link("peg", geom, peg_z, 0.3))
    robot.append(_fixed("tcp_joint", TOOL_LINK, TCP_LINK, f"0 0 {PEG_LENGTH}", "0 0 0"))
    robot.append(_link(TCP_LINK, None, 0.0, 0.01))
    robot.set("name", f"ur5_peg_{profile}")
    return ET.tostring(robot, encoding="unicode")


def _write_once(path: Path, data: bytes) -> None:
    """Atomic write: parallel workers building the same file never read half of it."""
    if not path.is_file():
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".tmp{os.getpid()}")
        tmp.write_bytes(data)
        tmp.replace(path)


def urdf_path(profile: str, chamfer: float = 0.0) -> str:
    """Write (once) and return the derived URDF for `profile` in the cache folder."""
    root = resources.cache_root()
    mesh_file = ""
    if chamfer > 0:
        data = chamfered_peg_mesh(profile, chamfer).export(file_type="stl")
        mesh = root / "robots" / f"peg_{profile}_{hashlib.sha256(data).hexdigest()[:12]}.stl"
        _write_once(mesh, data)
        mesh_file = str(mesh)
    text = build_urdf(profile, chamfer, mesh_file)
    digest = hashlib.sha256(text.encode()).hexdigest()[:12]
    path = root / "robots" / f"ur5_peg_{profile}_{digest}.urdf"
    _write_once(path, text.encode())
    return str(path)


class _UR5Peg(BaseAgent):
    peg_profile = "square"
    peg_chamfer = 0.0
    disable_self_collisions = True
    keyframes = dict(home=Keyframe(qpos=HOME_QPOS, pose=sapien.Pose()))
    camera_width = 128
    camera_height = 128
    camera_fov = float(CAMERA_FOV)
    camera_mount = MOUNTS[DEFAULT_MOUNT]
    """Wrist-camera resolution, vertical field of view (rad) and mount; the env sets them
    from the task file and the sensor profile before the scene is built."""

    @property
    def _sensor_configs(self):
        return [
            CameraConfig(
                uid=CAMERA_UID,
                pose=camera_pose_in_tool(self.camera_mount),
                width=self.camera_width,
                height=self.camera_height,
                fov=self.camera_fov,
                near=0.01,
                far=2.0,
                mount=self.robot.links_map[TOOL_LINK],
            )
        ]

    @property
    def _controller_configs(self):
        # Absolute joint targets: the shared executor does IK itself (Pinocchio) and checks
        # that every target was reached, instead of a controller that silently holds.
        drive = dict(stiffness=STIFFNESS, damping=DAMPING, force_limit=TORQUE_LIMITS.tolist())
        joints = list(ARM_JOINTS)
        arm = PDJointPosControllerConfig(
            joints, lower=None, upper=None, normalize_action=False, **drive
        )
        delta = PDJointPosControllerConfig(joints, lower=-0.1, upper=0.1, use_delta=True, **drive)
        # Position + velocity targets: the velocity feed-forward removes the lag a pure
        # position drive has (damping/stiffness = 0.1 s), which at 5 cm/s left the peg 1-2 mm
        # off its path, enough to catch the rim of a 4 mm-clearance hole.
        pos_vel = PDJointPosVelControllerConfig(
            joints, lower=None, upper=None, normalize_action=False, **drive
        )
        return deepcopy_dict(
            dict(
                pd_joint_pos_vel=dict(arm=pos_vel),
                pd_joint_pos=dict(arm=arm),
                pd_joint_delta_pos=dict(arm=delta),
            )
        )

    @property
    def urdf_path(self) -> str:  # written when the robot is loaded, not at import
        return urdf_path(self.peg_profile, self.peg_chamfer)

    def _after_init(self):
        self.tcp = self.robot.links_map[TCP_LINK]


@register_agent()
class UR5SquarePeg(_UR5Peg):
    """UR5 carrying the paper's 46 x 46 x 100 mm square peg."""

    uid = "ur5_peg_square"
    peg_profile = "square"


@register_agent()
class UR5RoundPeg(_UR5Peg):
    """UR5 carrying the paper's r 23 mm x 100 mm round peg."""

    uid = "ur5_peg_round"
    peg_profile = "round"


def robot_uid_for(profile: str, chamfer: float = 0.0) -> str:
    """The registered robot carrying a `profile` peg; a chamfered peg's robot is made and
    registered on first use (one per chamfer size, named by it in micrometres)."""
    base = {"square": UR5SquarePeg, "round": UR5RoundPeg}[profile]
    if chamfer <= 0:
        return base.uid
    uid = f"{base.uid}_chamfer{round(chamfer * 1e6)}um"
    if uid not in REGISTERED_AGENTS:
        cls = type(
            f"{base.__name__}Chamfer{round(chamfer * 1e6)}um",
            (base,),
            {"uid": uid, "peg_chamfer": chamfer},
        )
        register_agent()(cls)
    return uid
