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

from dataclasses import dataclass, field

import numpy as np
import tyro

from cfvs_maniskill.constants import PEG_LENGTH, PRE_INSERT_HEIGHT
from cfvs_maniskill.sensing.model import mount_error
from cfvs_maniskill.sensing.profile import load_profile


def camera_in_tip() -> np.ndarray:
    """The wrist camera's nominal mount (SAPIEN camera frame) in the peg-tip frame."""
    from cfvs_maniskill.robots.ur5 import camera_pose_in_tool

    C = np.asarray(camera_pose_in_tool().to_transformation_matrix(), dtype=np.float64)
    C[2, 3] -= PEG_LENGTH  # tool0 -> the tip, PEG_LENGTH along the tool's z
    return C


def pre_insertion_hole() -> np.ndarray:
    """The hole's frame in the peg-tip frame at the pre-insertion pose."""
    D = np.eye(4)
    D[:3, :3] = np.diag([1.0, -1.0, -1.0])  # hole z against the tool's z
    D[2, 3] = PRE_INSERT_HEIGHT
    return D


def hand_eye_residual(mount: np.ndarray) -> tuple[float, float]:
    """(lateral m, tilt deg) of the true hole from the tip when the believed one is at the
    pre-insertion pose: the tip's distance from the true axis and the angle between axes
    (what episode.pose_residual measures)."""
    C = camera_in_tip()
    # The exact inverse: SAPIEN's float32 pose is orthonormal to 1e-7 only (0.03 deg).
    H = C @ mount @ np.linalg.inv(C) @ pre_insertion_hole()
    z, d = H[:3, 2], -H[:3, 3]
    lateral = float(np.linalg.norm(d - (d @ z) * z))
    tilt = float(np.degrees(np.arctan2(np.hypot(z[0], z[1]), -z[2])))  # exact near 0
    return lateral, tilt


def floor_samples(translation: float, rotation_deg: float, n: int, seed: int) -> np.ndarray:
    """(n, 2) residuals (lateral m, tilt deg) over mount errors of exactly these sizes in
    random directions, drawn as the env draws them."""
    rng = np.random.default_rng(seed)
    return np.array(
        [hand_eye_residual(mount_error(translation, rotation_deg, rng)) for _ in range(n)]
    )


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
