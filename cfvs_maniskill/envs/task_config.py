"""Declarative task files (`tasks/*.yaml`): one file per task, one registered env per file."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import yaml

from cfvs_maniskill.constants import (
    DEFAULT_CLEARANCE,
    DEFAULT_HOLE_DEPTH,
    PEG_PROFILES,
    peg_half_extent,
)
from cfvs_maniskill.errors import FileFieldError

log = logging.getLogger(__name__)


class TaskConfigError(FileFieldError):
    """A task file that cannot be used."""


@dataclass(frozen=True)
class TaskConfig:
    """One peg-in-hole task. Lengths in metres, angles in degrees."""

    name: str
    """Task name; the env id is `<name>-v1`."""
    peg: str = "square"
    """Peg profile: round | square."""
    dof: int = 6
    """Degrees of freedom the task asks to control (paper: 3 = x y z, 4 = + yaw about the
    vertical, 6 = full pose). 3 / 4-DoF holes are upright, so agents keep the peg vertical."""
    clearance: float = DEFAULT_CLEARANCE
    """Hole minus peg width (diametral), metres."""
    peg_chamfer: float = 0.0
    """45-degree chamfer on the peg's tip edges, metres (0: the paper's sharp-edged peg).
    Tight fits use one, as real parts do: the tip then starts into the hole with that much
    more lateral / yaw error and the chamfer guides it in."""
    pcm: bool = True
    """PhysX's persistent contact manifold (its default contact generation). Tight fits turn
    it off for exact per-step contacts: at 1 mm it kept stale contacts on both rim edges
    that held a peg with 0.4 mm of free play on each side (re-placed, the same pose had
    none), which was most of the 1 mm failures."""
    contact_offset: float = 0.002
    """PhysX contact offset of every collision shape, metres: shape pairs closer than the sum
    of their offsets get contacts. 2 mm catches the peg's fastest approach at 500 Hz. Tight
    fits use 0.2 mm: with 2 mm or 0.5 mm, PhysX's convex-convex contacts held a peg centred
    within 0.06 mm 1.7 mm into a 0.5 mm-clearance entry, on contacts reported touching
    (separation 0, the peg chamfer's 45 deg normals) at the hole's corners while the walls
    were 0.25 mm away; the true pose then went in 73 of 80 times, with 0.2 mm 80 of 80."""
    hole_depth: float = DEFAULT_HOLE_DEPTH
    """Depth of the hole, metres."""
    objects: tuple[str, ...] = ("test",)
    """Default hole objects: names or splits (train | test | all)."""
    workspace_x: tuple[float, float] = (0.40, 0.60)
    """Range of the hole object's x position on the table (world frame, metres)."""
    workspace_y: tuple[float, float] = (-0.15, 0.15)
    """Range of the hole object's y position on the table (world frame, metres)."""
    yaw_deg: tuple[float, float] = (0.0, 0.0)
    """Range of the object's rotation about the vertical, degrees."""
    tilt_deg: tuple[float, float] = (0.0, 0.0)
    """Range of the hole axis' angle from vertical, degrees (6-DoF: 0-50)."""
    init_error: dict[str, float] = field(default_factory=lambda: {"small": 0.15, "large": 0.30})
    """Named initial peg-tip-to-hole distances, metres (paper: 15 cm small, 30 cm large)."""
    init_cone_deg: float = 25.0
    """The peg starts within this angle of the hole's axis, looking at the hole +- init_aim_deg."""
    init_aim_deg: float = 5.0
    """Random tilt of the starting tool axis away from the line to the hole, degrees."""
    init_roll_deg: float = 45.0
    """Random rotation of the starting tool about its axis, +- degrees."""
    depth_noise_std: float = 0.001
    """Gaussian noise on the point cloud, metres (paper: N(0, 1 mm^2))."""
    fine_max_translation: float = 0.03
    """Fine dataset: largest random tool offset from the pre-insertion pose, metres. Sized to
    cover what the coarse stage (OAKN) leaves, with margin."""
    fine_max_tilt_deg: float = 10.0
    """Fine dataset: largest random tilt of the tool axis, degrees."""
    fine_max_yaw_deg: float = 15.0
    """Fine dataset: largest random turn about the tool axis, degrees."""
    camera_width: int = 128
    camera_height: int = 128
    max_episode_steps: int = 1500
    """Control steps (20 Hz) before the episode is truncated."""
    source: str = ""

    @property
    def env_id(self) -> str:
        return f"{self.name}-v1"


def load_task(path: Path) -> TaskConfig:
    data: Any = yaml.safe_load(Path(path).read_text())
    if not isinstance(data, dict):
        raise TaskConfigError(path, "<top>", "expected a mapping of task fields")
    known = {f.name: f for f in fields(TaskConfig) if f.name != "source"}
    kwargs: dict[str, Any] = {"name": Path(path).stem, "source": str(path)}
    for k, v in data.items():
        if k not in known:
            raise TaskConfigError(path, k, f"unknown key; expected one of {', '.join(known)}")
        if k in ("workspace_x", "workspace_y", "yaw_deg", "tilt_deg"):
            if not (
                isinstance(v, list) and len(v) == 2 and all(isinstance(x, int | float) for x in v)
            ):
                raise TaskConfigError(path, k, f"expected [min, max], got {v!r}")
            v = (float(v[0]), float(v[1]))
        elif known[k].type in ("float", "int") and (
            isinstance(v, bool) or not isinstance(v, int | float)
        ):
            raise TaskConfigError(path, k, f"expected a number, got {v!r}")
        elif known[k].type == "bool" and not isinstance(v, bool):
            raise TaskConfigError(path, k, f"expected true or false, got {v!r}")
        elif k == "objects":
            v = tuple([v] if isinstance(v, str) else v)
        elif k == "init_error":
            if not isinstance(v, dict) or not all(
                isinstance(x, int | float) and x > 0 for x in v.values()
            ):
                raise TaskConfigError(path, k, f"expected a mapping name -> metres, got {v!r}")
            v = {str(a): float(b) for a, b in v.items()}
        kwargs[k] = v
    cfg = TaskConfig(**kwargs)
    if cfg.dof not in (3, 4, 6):
        raise TaskConfigError(path, "dof", f"expected 3, 4 or 6, got {cfg.dof!r}")
    if cfg.peg not in PEG_PROFILES:
        raise TaskConfigError(path, "peg", f"expected one of {PEG_PROFILES}, got {cfg.peg!r}")
    if not (0 <= cfg.peg_chamfer <= 0.25 * peg_half_extent(cfg.peg)):
        raise TaskConfigError(
            path,
            "peg_chamfer",
            f"expected 0 <= peg_chamfer <= {0.25 * peg_half_extent(cfg.peg):.4f} m "
            f"(a quarter of the peg's half width), got {cfg.peg_chamfer}",
        )
    if not (0 < cfg.clearance < 0.02):
        raise TaskConfigError(
            path, "clearance", f"expected 0 < clearance < 0.02 m, got {cfg.clearance}"
        )
    if not (0 < cfg.contact_offset <= 0.02):
        raise TaskConfigError(
            path,
            "contact_offset",
            f"expected 0 < contact_offset <= 0.02 m (PhysX needs one above 0), "
            f"got {cfg.contact_offset}",
        )
    if cfg.contact_offset > cfg.clearance / 2:
        # Measured at 0.5 mm clearance: 0.5 mm and 2 mm offsets stalled centred pegs in the
        # entry, 0.2 mm did not (TaskConfig.contact_offset).
        raise TaskConfigError(
            path,
            "contact_offset",
            f"{cfg.contact_offset} m is more than half the clearance ({cfg.clearance} m): "
            f"expected contact_offset <= {cfg.clearance / 2:g} m, or PhysX holds pegs "
            f"centred in the hole's entry on contacts across the play",
        )
    return cfg


def load_tasks(*directories: Path) -> dict[str, TaskConfig]:
    """All task files in `directories` (default: the bundled ones, then the user folder's,
    resources.py), by task name; a later file with an earlier one's name is left out."""
    from cfvs_maniskill import resources

    tasks: dict[str, TaskConfig] = {}
    for d in directories or resources.search_dirs("tasks"):
        for p in sorted(Path(d).glob("*.yaml")):
            if p.stem in tasks:
                log.warning("task file %s left out: task '%s' is %s", p, p.stem,
                            tasks[p.stem].source)  # fmt: skip
                continue
            tasks[p.stem] = load_task(p)
    return tasks
