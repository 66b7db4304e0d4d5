"""Where the wrist camera sits on the tool: its mount, a field of the sensor profile
(`mount:`). Named mounts live here; a profile may also give its own bracket's geometry.

A mount is the camera's position in the flange (tool0) frame and the point it aims at; the
image's horizontal axis stays along the tool's y. Pure geometry, light: the env places the
rendered camera with it and the agents read it from the robot's drawing (TaskSpec).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cfvs_maniskill.constants import PEG_LENGTH


@dataclass(frozen=True)
class Mount:
    name: str
    position: tuple[float, float, float]
    """Camera centre in tool0 (m)."""
    aim: tuple[float, float, float]
    """The point in tool0 its optical axis passes through (m)."""
    source: str = ""
    """Where the geometry comes from (a bracket's drawing, or why it was chosen)."""

    def in_tool(self) -> np.ndarray:
        """4x4 camera pose in tool0, SAPIEN's camera axes (x forward, y left, z up)."""
        p, aim = np.asarray(self.position, float), np.asarray(self.aim, float)
        x = (aim - p) / np.linalg.norm(aim - p)
        y = np.array([0.0, 1.0, 0.0]) - x[1] * x  # the image's horizontal stays on tool y
        y /= np.linalg.norm(y)
        T = np.eye(4)
        T[:3, :3] = np.stack([x, y, np.cross(x, y)], axis=1)
        T[:3, 3] = p
        return T

    def in_tcp(self) -> np.ndarray:
        """4x4 camera pose in the peg-tip (tcp) frame: PEG_LENGTH past the flange."""
        T = self.in_tool()
        T[2, 3] -= PEG_LENGTH
        return T

    def in_view(
        self, points: np.ndarray, depth_range: tuple[float, float], fov_deg: tuple[float, float]
    ) -> np.ndarray:
        """Whether each tool0-frame point of `points` (K, 3) is where this camera returns
        depth: its depth along the optical axis within `depth_range` (m) and its direction
        within the field of view `fov_deg` (horizontal x vertical, degrees)."""
        T = self.in_tool()
        p = (np.asarray(points, float) - T[:3, 3]) @ T[:3, :3]  # x forward, y left, z up
        depth = p[:, 0]
        across = np.degrees(np.abs(np.arctan2(p[:, 1:], depth[:, None])))
        return (
            (depth >= depth_range[0])
            & (depth <= depth_range[1])
            & (across[:, 0] <= fov_deg[0] / 2)
            & (across[:, 1] <= fov_deg[1] / 2)
        )

    def check(self) -> tuple[str, str] | None:
        """(field, what is wrong) with the geometry, or None."""
        for field in ("position", "aim"):
            v = np.asarray(getattr(self, field), dtype=float)
            if not np.all(np.isfinite(v)) or np.abs(v).max() > MAX_REACH:
                return field, f"expected finite metres within {MAX_REACH} m of the flange"
        x = np.subtract(self.aim, self.position)
        if np.linalg.norm(x) < 1e-3:
            return "aim", "expected at least 1 mm from position"
        if abs(x[1]) > 0.99 * np.linalg.norm(x):
            return "aim", "the optical axis must not run along the tool's y axis"
        return None


MAX_REACH = 0.5
"""A camera bracket on a flange holds the camera within this distance of it (m)."""

MOUNTS = {
    m.name: m
    for m in (
        Mount(
            "flange_side",
            (0.11, 0.0, 0.05),
            (0.0, 0.0, 0.30),
            "11 cm off the tool axis, 5 cm forward of the flange, aimed 20 cm past the tip: "
            "the hole is seen beside the peg from 5 cm above it; the peg's tip is outside "
            "the view, so the cloud is placed by the hand-eye calibration alone",
        ),
        Mount(
            "tip_view",
            (0.11, 0.0, 0.05),
            (0.0, 0.0, 0.17),
            "flange_side's bracket pitched down: the optical axis meets the tool axis 7 cm "
            "past the tip, so at the pre-insertion pose the tip is 23 deg and the opening "
            "12 deg below the image's centre (the D405's vertical half field is 29 deg), "
            "0.11 m and 0.13 m away; the peg's face towards the camera is in view from the "
            "coarse view on, and the opening is seen beside the peg, not behind it",
        ),
        Mount(
            "tip_view_long",
            (0.17, 0.0, 0.05),
            (0.0, 0.0, 0.17),
            "tip_view's bracket lengthened to 17 cm off the tool axis, for a camera whose "
            "minimum range hides tip_view's peg (a D435's Min-Z is 12.7 cm even with its "
            "disparity shift; on tip_view the tip is at 11 cm depth): the peg's last 2 cm "
            "at 13.7-14.9 cm depth, 16-24 deg below the image's centre, the opening at the "
            "pre-insertion pose at 18.5 cm and, seen past the peg's tip, whole (moving the "
            "camera back instead hides half the opening behind the peg)",
        ),
        Mount(
            "peg_view",
            (0.075, 0.0, 0.02),
            (0.0, 0.0, 0.13),
            "75 mm off the tool axis, 20 mm forward of the flange (a D405, 42 x 42 x 23 mm, "
            "on a bracket beside a 63 mm UR flange), aimed at the tool axis 30 mm past the "
            "tip: at the pre-insertion pose the tip is 0.11 m and the opening 0.13 m away, "
            "beyond the D405's 7 cm minimum range, both near the image's centre",
        ),
    )
}
"""Named mounts; a profile's `mount.name` picks one (or gives its own geometry)."""

DEFAULT_MOUNT = "tip_view"
