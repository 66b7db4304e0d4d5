"""The hand-eye floor: how far from the pre-insertion pose a peg ends when the hole is
estimated *perfectly* in the camera's frame but the robot trusts the nominal camera mount.
No camera-only agent can do better under a profile's hand-eye error; the closed-loop
residual targets are read against it (docs/sensing.md).

    .venv/bin/python -m cfvs_maniskill.sensing.floor --sensors realistic handeye_2mm_1deg

The servo ends where the *believed* hole sits at the pre-insertion pose D (in the peg-tip
frame: the opening PRE_INSERT_HEIGHT ahead of the tip, its axis against the tool's). A
camera truly at C M (C the nominal mount in the tip frame, M the mount error, as the env
applies it) sees the true hole H at (C M)^-1 H and places it at C (C M)^-1 H, so at the end
the true hole is H = C M C^-1 D.

The depth camera's own calibration errors add to it (`depth_residuals`): a depth scale and
offset move the hole along its ray (at the pre-insertion view the ray is oblique, so part
of that is lateral), and focal and principal-point errors turn and stretch the rays. The
perceived point is P(p); the servo ends where C P((C M)^-1 H) = D, so H = C M P^-1(C^-1 D).

A robot that calibrates its camera against the table (perception/table_calibration.py)
applies K = s Q, fitted to the table as P shows it from the coarse view, to what it sees:
then H = C M P^-1(K^-1 C^-1 D) (`table_calibrations`, `depth_residuals(..., calibration)`).

The closed-loop floor (`closed_loop_samples`) is that of a servo whose camera sees the
peg's tip and the opening together and drives their offset, as both appear, to the
pre-insertion one. The mount error M then only changes the viewpoint and the step's
direction (the servo converges wherever the perceived offset is right), and a camera
error P that is linear in the camera frame (a depth scale, a focal or principal-point
error: x' = k s x + c s z / f) keeps points on a line on a line: the tip ends on the true
axis. What is left is P's part that is not linear (a depth offset) and the noise of the
measured tip, axis and opening.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
import tyro

from cfvs_maniskill import geometry as G
from cfvs_maniskill.constants import PRE_INSERT_HEIGHT
from cfvs_maniskill.robots.mounts import DEFAULT_MOUNT, MOUNTS
from cfvs_maniskill.sensing.model import depth_errors, mount_errors
from cfvs_maniskill.sensing.profile import SensorProfile, load_profile


def camera_in_tip(mount: str = DEFAULT_MOUNT) -> np.ndarray:
    """The wrist camera on a named mount (SAPIEN camera frame) in the peg-tip frame."""
    return MOUNTS[mount].in_tcp()


def pre_insertion_hole() -> np.ndarray:
    """The hole's frame in the peg-tip frame at the pre-insertion pose."""
    D = np.eye(4)
    D[:3, :3] = np.diag([1.0, -1.0, -1.0])  # hole z against the tool's z
    D[2, 3] = PRE_INSERT_HEIGHT
    return D


def hand_eye_residuals(mounts: np.ndarray) -> np.ndarray:
    """(n, 2): lateral m and tilt deg of the true hole from the tip for (n, 4, 4) mount
    errors, when the believed hole is at the pre-insertion pose: the tip's distance from the
    true axis and the angle between the axes (what episode.pose_residual measures)."""
    C = camera_in_tip()
    # The exact inverse: SAPIEN's float32 pose is orthonormal to 1e-7 only (0.03 deg).
    return _residuals(C @ mounts @ np.linalg.inv(C) @ pre_insertion_hole())


_SAPIEN_TO_CV = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
"""A SAPIEN camera frame's (x forward, y left, z up) axes -> OpenCV's (x right, y down)."""


def unperceive(p: np.ndarray, scale, offset, focal_ratio, principal, focal_px: float):
    """(n, 3) points where the camera reports them (SAPIEN camera frame) -> where they
    truly are: the inverse of depth z' = scale z + offset and ray x'/z' = (x/z) k + c / f
    (k the true / reported focal ratio, c the principal-point offset in pixels)."""
    q = p @ _SAPIEN_TO_CV.T
    z = (q[:, 2] - offset) / scale
    ray = (q[:, :2] / q[:, 2:3] - principal * focal_ratio[:, None] / focal_px) / focal_ratio[
        :, None
    ]
    true = np.concatenate([ray * z[:, None], z[:, None]], axis=1)
    return true @ _SAPIEN_TO_CV


def perceive(p: np.ndarray, scale, offset, focal_ratio, principal, focal_px: float):
    """(n, k, 3) true points (SAPIEN camera frame) -> where the camera reports them: the
    inverse of `unperceive`, per row of (n,) errors."""
    q = p @ _SAPIEN_TO_CV.T
    k = focal_ratio[:, None, None]
    ray = q[..., :2] / q[..., 2:3] * k + principal[:, None, :] * k / focal_px
    z = q[..., 2:3] * scale[:, None, None] + offset[:, None, None]
    return np.concatenate([ray * z, z], axis=-1) @ _SAPIEN_TO_CV


def table_calibrations(
    mounts: np.ndarray, depth: dict, focal_px: float, camera_height: float
) -> np.ndarray:
    """(n, 3, 3) corrections K (camera frame) the table calibration finds from a coarse view
    with the tool pointing straight down and the camera `camera_height` above the table:
    the plane fitted to the table as the camera reports it, turned upright and scaled onto
    its known height about the camera (perception/table_calibration.py, without noise)."""
    C = camera_in_tip()
    tip = np.eye(4)
    tip[:3, :3] = np.diag([1.0, -1.0, -1.0])  # tool z down
    tip[2, 3] = camera_height + C[2, 3]  # the camera's centre at camera_height
    believed = tip @ C
    g = np.linspace(-0.12, 0.12, 9)
    X = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2) + believed[:2, 3]
    X = np.column_stack([X, np.zeros(len(X)), np.ones(len(X))])  # table points, world
    true_cam = np.linalg.inv(believed[None] @ mounts)  # world -> the true camera frame
    q = np.einsum("nij,kj->nki", true_cam, X)[..., :3]
    args = (depth["scale"], depth["offset"], depth["focal_ratio"], depth["principal"], focal_px)
    seen = perceive(q, *args)  # reported, believed camera frame
    mean = seen.mean(axis=1, keepdims=True)
    normal = np.linalg.svd(seen - mean)[2][:, 2]  # least squares plane, camera frame
    up = np.linalg.inv(believed)[:3, :3] @ [0.0, 0.0, 1.0]  # world up, camera frame
    normal *= np.sign(normal @ up)[:, None]
    reported = -np.sum(normal * mean[:, 0], axis=1)  # the camera's distance from it
    return (camera_height / reported)[:, None, None] * G.shortest_turns(normal, up)


def depth_residuals(
    mounts: np.ndarray, depth: dict, focal_px: float, calibration: np.ndarray | None = None
) -> np.ndarray:
    """hand_eye_residuals with the depth camera's errors too: `depth` holds (n,) arrays
    scale, offset, focal_ratio and (n, 2) principal (sensor pixels); `calibration`, the
    (n, 3, 3) corrections K the robot applies to what its camera reports."""
    C = camera_in_tip()
    Cinv = np.linalg.inv(C)
    D = pre_insertion_hole()
    believed = Cinv @ D  # where the camera must see the hole, its frame
    origin = np.repeat(believed[None, :3, 3], len(mounts), axis=0)
    tip = origin + 0.01 * believed[:3, 2]  # a point 10 mm along the hole axis
    if calibration is not None:  # what the camera must report for K to put it there
        Kinv = np.linalg.inv(calibration)
        origin, tip = np.einsum("nij,nj->ni", Kinv, origin), np.einsum("nij,nj->ni", Kinv, tip)
    args = (depth["scale"], depth["offset"], depth["focal_ratio"], depth["principal"], focal_px)
    o, a = unperceive(origin, *args), unperceive(tip, *args)
    H = np.repeat(believed[None], len(mounts), axis=0)
    H[:, :3, 3] = o
    z = (a - o) / np.linalg.norm(a - o, axis=1, keepdims=True)
    # Keep the believed frame's x and y about the true axis (only the axis and origin count).
    x = believed[:3, 0] - np.sum(believed[:3, 0] * z, axis=1, keepdims=True) * z
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    H[:, :3, 0], H[:, :3, 1], H[:, :3, 2] = x, np.cross(z, x), z
    return _residuals(C @ mounts @ H)


def _residuals(H: np.ndarray) -> np.ndarray:
    z, d = H[:, :3, 2], -H[:, :3, 3]
    lateral = np.linalg.norm(d - np.sum(d * z, axis=1, keepdims=True) * z, axis=1)
    tilt = np.degrees(np.arctan2(np.hypot(z[:, 0], z[:, 1]), -z[:, 2]))  # exact near 0
    return np.stack([lateral, tilt], axis=1)


def hand_eye_residual(mount: np.ndarray) -> tuple[float, float]:
    """hand_eye_residuals for one mount error."""
    lateral, tilt = hand_eye_residuals(np.asarray(mount)[None])[0]
    return float(lateral), float(tilt)


def floor_samples(translation: float, rotation_deg: float, n: int, seed: int) -> np.ndarray:
    """(n, 2) residuals (lateral m, tilt deg) over mount errors of exactly these sizes in
    random directions, drawn by the env's own `mount_errors`."""
    mounts = mount_errors(translation, rotation_deg, np.random.default_rng(seed), n)
    return hand_eye_residuals(mounts)


def profile_floor_samples(
    profile: SensorProfile, n: int, seed: int, table_height: float | None = None
) -> np.ndarray:
    """(n, 2) residuals over a profile's hand-eye and depth-camera errors, drawn within its
    bounds as the env draws them (uniform for the depth camera's); with `table_height`, for
    a robot that calibrates against the table seen from that camera height."""
    he, d = profile.hand_eye, profile.depth
    mounts = mount_errors(he.translation, he.rotation_deg, np.random.default_rng(seed), n)
    stereo = d.model == "stereo"
    if not stereo and table_height is None:
        return hand_eye_residuals(mounts)
    u = np.random.default_rng([seed, 1]).uniform(-1.0, 1.0, (n, 5))
    depth = depth_errors(d, u if stereo else np.zeros((n, 5)))  # iid: no camera errors
    focal_px = d.focal_px if stereo else 1.0  # any focal: no principal-point error
    K = None if table_height is None else table_calibrations(mounts, depth, focal_px, table_height)
    return depth_residuals(mounts, depth, focal_px, K)


PLAIN_PART_NOISE = 2.5
"""Stereo noise on a plain part against a textured target (the profiles' sources: D405
users report 2.5x on low-texture surfaces)."""


def point_noise(profile: SensorProfile, distance: float, iid_std: float = 0.001) -> float:
    """One point's depth noise, m, at `distance` (stereo: axial noise on a plain part; iid:
    the profile's std, else the task's)."""
    d = profile.depth
    if d.model == "stereo":
        return PLAIN_PART_NOISE * distance**2 * d.disparity_noise_px / (d.focal_px * d.baseline)
    return d.std if d.std is not None else iid_std


def closed_loop_samples(
    profile: SensorProfile, n: int, seed: int, points: int = 100, camera: np.ndarray | None = None
) -> np.ndarray:
    """(n, 2) residuals (lateral m, tilt deg) of the closed-loop servo under a profile's
    mount and camera errors, drawn as `profile_floor_samples` draws them, with the tip, the
    peg's axis and the opening each measured from `points` points of that noise."""
    C = camera_in_tip() if camera is None else camera
    he, d = profile.hand_eye, profile.depth
    rng = np.random.default_rng(seed)
    mounts = mount_errors(he.translation, he.rotation_deg, rng, n)
    stereo = d.model == "stereo"
    u = np.random.default_rng([seed, 1]).uniform(-1.0, 1.0, (n, 5))
    depth = depth_errors(d, u if stereo else np.zeros((n, 5)))
    focal_px = d.focal_px if stereo else 1.0
    args = (depth["scale"], depth["offset"], depth["focal_ratio"], depth["principal"], focal_px)
    cams = np.linalg.inv(C[None] @ mounts)  # tip frame -> the true camera frame
    peg = np.array([[0.0, 0.0, 0.0, 1.0], [0.0, 0.0, -0.05, 1.0]])  # tip, 50 mm up the peg
    tip, back = np.einsum("nij,kj->nki", cams, peg)[..., :3].transpose(1, 0, 2)
    D = pre_insertion_hole()
    o = np.einsum("nij,j->ni", cams, D[:, 3])[:, :3]  # the hole's opening, camera frame
    z = np.einsum("nij,j->ni", cams[:, :3, :3], D[:3, 2])  # its axis (out of the face)
    # Noise of what is fitted to `points` points each: a centre (the tip, the opening), the
    # peg's axis along its visible 50 mm and the face's normal over a 15 mm-radius ring.
    pt = point_noise(profile, float(np.linalg.norm(C[:3, 3])))
    centre, along, ring = pt / np.sqrt(points), pt * np.sqrt(12 / points) / 0.05, pt / 0.015
    ring /= np.sqrt(points / 2)
    seen_tip = perceive(tip[:, None], *args)[:, 0] + rng.normal(0.0, centre, (n, 3))
    seen_back = perceive(back[:, None], *args)[:, 0]
    peg_axis = _tilted(_unit(seen_tip - seen_back), along, rng)
    o_noise, z_noise = rng.normal(0.0, centre, (n, 3)), rng.standard_normal((n, 3))
    for _ in range(30):  # move the hole (the camera rides with the peg) to the fixed point
        seen_o = perceive(o[:, None], *args)[:, 0]
        seen_z = _unit(perceive((o + 0.01 * z)[:, None], *args)[:, 0] - seen_o)
        seen_o, seen_z = seen_o + o_noise, _tilted(seen_z, ring, None, z_noise)
        o = o + (seen_tip + PRE_INSERT_HEIGHT * seen_z) - seen_o  # tip 30 mm out on the axis
        z = _unit(z + (-peg_axis - seen_z))  # the axes opposed
    lateral_vec = (tip - o) - np.sum((tip - o) * z, axis=1, keepdims=True) * z
    axis = _unit(tip - back)
    tilt = np.degrees(np.arccos(np.clip(-np.sum(axis * z, axis=1), -1.0, 1.0)))
    return np.stack([np.linalg.norm(lateral_vec, axis=1), tilt], axis=1)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _tilted(v: np.ndarray, sigma: float, rng, draws: np.ndarray | None = None) -> np.ndarray:
    """Unit vectors `v` turned by N(0, sigma) rad about random perpendicular axes (the
    same turn for the same `draws`, (n, 3) standard normals)."""
    w = rng.standard_normal(v.shape) if draws is None else draws
    return _unit(v + sigma * (w - np.sum(w * v, axis=1, keepdims=True) * v))


TABLE_VIEW_HEIGHT = 0.27
"""The camera's height above the table in the coarse view, for the table calibration's
floor (the first views of 16 D405 6-DoF episodes: 185-332 mm, median 270)."""


@functools.cache
def floor_p90(
    sensor: str, samples: int = 20000, table_view_height: float | None = None
) -> tuple[float, float] | None:
    """(lateral mm, tilt deg) p90 of a profile's floor (hand-eye and depth-camera errors;
    with `table_view_height`, for a robot calibrated on the table seen from there); None
    without either error or for a sensor name that is not a loadable profile (old
    records)."""
    try:
        profile = load_profile(sensor)
    except (OSError, ValueError):
        return None
    he, d = profile.hand_eye, profile.depth
    calibration = (
        d.depth_scale_error,
        d.depth_offset_error,
        d.focal_error,
        d.principal_point_error_px,
    )
    if he.translation == 0 and he.rotation_deg == 0 and not any(calibration):
        return None
    s = profile_floor_samples(profile, samples, seed=0, table_height=table_view_height)
    return float(1000 * np.percentile(s[:, 0], 90)), float(np.percentile(s[:, 1], 90))


@dataclass
class FloorArgs:
    """Print the floors of sensor profiles: the residual a perfect estimator of the hole
    leaves when it trusts the nominal camera mount (today's design), calibrated on the
    table, and when the camera sees the peg and the loop closes on their offset."""

    sensors: list[str] = field(
        default_factory=lambda: ["realistic", "textured", "d435", "handeye_2mm_1deg"]
    )
    """Profile names (sensors/*.yaml) or paths."""
    samples: int = 20000
    """Mount errors drawn per profile."""
    seed: int = 0
    """Seed of the draws."""
    table_view_height: float = TABLE_VIEW_HEIGHT
    """The camera's height above the table in the coarse view (the table calibration's
    column)."""
    points: int = 100
    """Closed loop: points each of the tip, the peg's axis and the opening is measured from."""


def main(args: FloorArgs) -> None:
    print(
        "| profile | hand-eye error | depth scale / intrinsics error "
        "| lateral p50 / p90 (hand-eye only) | tilt p50 / p90 "
        "| calibrated on the table: lateral, tilt p50 / p90 "
        "| closed loop on the peg: lateral, tilt p50 / p90 |"
    )
    print("|---|---|---|---|---|---|---|")
    for name in args.sensors:
        profile = load_profile(name)
        he, d = profile.hand_eye, profile.depth
        s = profile_floor_samples(profile, args.samples, args.seed)
        h = floor_samples(he.translation, he.rotation_deg, args.samples, args.seed)
        lat = 1000 * np.percentile(s[:, 0], [50, 90])
        lat_he = 1000 * np.percentile(h[:, 0], [50, 90])
        tilt = np.percentile(s[:, 1], [50, 90])
        t = profile_floor_samples(profile, args.samples, args.seed, args.table_view_height)
        t_lat, t_tilt = 1000 * np.percentile(t[:, 0], [50, 90]), np.percentile(t[:, 1], [50, 90])
        c = closed_loop_samples(profile, args.samples, args.seed, args.points)
        c_lat, c_tilt = 1000 * np.percentile(c[:, 0], [50, 90]), np.percentile(c[:, 1], [50, 90])
        depth = "-"
        if d.model == "stereo":
            depth = (
                f"+-{100 * d.depth_scale_error:g}% / +-{100 * d.focal_error:g}% f, "
                f"+-{d.principal_point_error_px:g} px"
            )
        print(
            f"| `{name}` | {1000 * he.translation:g} mm / {he.rotation_deg:g} deg | {depth} "
            f"| {lat[0]:.2f} / {lat[1]:.2f} mm ({lat_he[0]:.2f} / {lat_he[1]:.2f}) "
            f"| {tilt[0]:.2f} / {tilt[1]:.2f} deg "
            f"| {t_lat[0]:.2f} / {t_lat[1]:.2f} mm, {t_tilt[0]:.2f} / {t_tilt[1]:.2f} deg "
            f"| {c_lat[0]:.2f} / {c_lat[1]:.2f} mm, {c_tilt[0]:.2f} / {c_tilt[1]:.2f} deg |"
        )


if __name__ == "__main__":
    main(tyro.cli(FloorArgs))
