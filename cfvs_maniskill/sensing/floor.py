"""The hand-eye floor: how far from the pre-insertion pose a peg ends when the hole is
estimated *perfectly* in the camera's frame but the robot trusts the nominal camera mount.
No camera-only agent can do better under a profile's hand-eye error; the closed-loop
residual targets are read against it (docs/sensing.md).

    .venv/bin/python -m cfvs_maniskill.sensing.floor --sensors realistic handeye_2mm_1deg

The servo ends where the *believed* hole sits at the pre-insertion pose D (in the peg-tip
frame: the opening PRE_INSERT_HEIGHT ahead of the tip, its axis against the tool's). A
camera truly at C M (C the nominal mount in the tip frame, M the mount error, as the env
applies it) sees the true hole H at (C M)^-1 H and places it at C (C M)^-1 H, so at the end
the true hole is H = C M C^-1 D."""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
import tyro

from cfvs_maniskill.constants import PRE_INSERT_HEIGHT
from cfvs_maniskill.robots.poses import flange_pose
from cfvs_maniskill.sensing.model import mount_errors
from cfvs_maniskill.sensing.profile import load_profile


def camera_in_tip() -> np.ndarray:
    """The wrist camera's nominal mount (SAPIEN camera frame) in the peg-tip frame."""
    from cfvs_maniskill.robots.ur5 import camera_pose_in_tool

    tool0 = flange_pose(np.eye(4))  # the flange in the tip frame
    return tool0 @ np.asarray(camera_pose_in_tool().to_transformation_matrix(), np.float64)


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
    H = C @ mounts @ np.linalg.inv(C) @ pre_insertion_hole()
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


@functools.cache
def floor_p90(sensor: str, samples: int = 20000) -> tuple[float, float] | None:
    """(lateral mm, tilt deg) p90 of a profile's hand-eye floor; None without a hand-eye
    error or for a sensor name that is not a loadable profile (old records)."""
    try:
        he = load_profile(sensor).hand_eye
    except (OSError, ValueError):
        return None
    if he.translation == 0 and he.rotation_deg == 0:
        return None
    s = floor_samples(he.translation, he.rotation_deg, samples, seed=0)
    return float(1000 * np.percentile(s[:, 0], 90)), float(np.percentile(s[:, 1], 90))


@dataclass
class FloorArgs:
    """Print the hand-eye floor of sensor profiles: the closed-loop residual a perfect
    estimator of the hole leaves when it trusts the nominal camera mount."""

    sensors: list[str] = field(default_factory=lambda: ["realistic", "handeye_2mm_1deg"])
    """Profile names (sensors/*.yaml) or paths."""
    samples: int = 20000
    """Mount errors drawn per profile."""
    seed: int = 0
    """Seed of the draws."""


def main(args: FloorArgs) -> None:
    print("| profile | hand-eye error | lateral p50 / p90 | tilt p50 / p90 |")
    print("|---|---|---|---|")
    for name in args.sensors:
        he = load_profile(name).hand_eye
        s = floor_samples(he.translation, he.rotation_deg, args.samples, args.seed)
        lat = 1000 * np.percentile(s[:, 0], [50, 90])
        tilt = np.percentile(s[:, 1], [50, 90])
        print(
            f"| `{name}` | {1000 * he.translation:g} mm / {he.rotation_deg:g} deg "
            f"| {lat[0]:.2f} / {lat[1]:.2f} mm | {tilt[0]:.2f} / {tilt[1]:.2f} deg |"
        )


if __name__ == "__main__":
    main(tyro.cli(FloorArgs))
