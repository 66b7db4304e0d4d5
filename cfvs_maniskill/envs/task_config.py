"""Declarative task files (`tasks/*.yaml`): one file per task, one registered env per file."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import Field

from cfvs_maniskill.constants import (
    DEFAULT_CLEARANCE,
    DEFAULT_HOLE_DEPTH,
    PEG_LENGTH,
    hole_half_extent,
    peg_half_extent,
)
from cfvs_maniskill.errors import FileFieldError
from cfvs_maniskill.validation import STRICT, validate_file

log = logging.getLogger(__name__)


class TaskConfigError(FileFieldError):
    """A task file that cannot be used."""


Metres = Annotated[float, Field(ge=-1.0, le=1.0)]
"""A position on the table, world frame: within the UR5's reach (0.85 m) of its base."""
Degrees = Annotated[float, Field(ge=-180.0, le=180.0)]
LOOSE_CONTACT_OFFSET = 0.002
"""The contact offset of a task without one, or half its clearance if that is less
(TaskConfig.contact_offset)."""


@dataclass(frozen=True)
class TaskConfig:
    """One peg-in-hole task. Lengths in metres, angles in degrees. Types and ranges are the
    task file's schema (validation.py); rules between fields are in `load_task`."""

    __pydantic_config__ = STRICT
    NOT_IN_FILE = ("name", "source")  # from the file's name and place, not its text

    name: str
    """Task name; the env id is `<name>-v1`."""
    peg: Literal["round", "square"] = "square"
    """Peg profile: round | square."""
    dof: Literal[3, 4, 6] = 6
    """Degrees of freedom the task asks to control (paper: 3 = x y z, 4 = + yaw about the
    vertical, 6 = full pose). 3 / 4-DoF holes are upright, so agents keep the peg vertical."""
    clearance: Annotated[float, Field(gt=0.0, lt=0.02)] = DEFAULT_CLEARANCE
    """Hole minus peg width (diametral), metres."""
    peg_chamfer: Annotated[float, Field(ge=0.0)] = 0.0
    """45-degree chamfer on the peg's tip edges, metres (0: the paper's sharp-edged peg).
    Tight fits use one, as real parts do: the tip then starts into the hole with that much
    more lateral / yaw error and the chamfer guides it in."""
    pcm: bool = False
    """PhysX's persistent contact manifold (PhysX's default contact generation). Off: exact
    per-step contacts. With it, a peg pressed into a 4 mm hole's floor at a slight tilt sank
    0.06-0.15 mm into a wall, and at 1 mm it kept stale contacts on both rim edges that held
    a peg with 0.4 mm of free play on each side (re-placed, the same pose had none)."""
    contact_offset: Annotated[float, Field(gt=0.0, le=0.02)] | None = None
    """PhysX contact offset of every collision shape, metres: shape pairs closer than the sum
    of their offsets get contacts. Unset: 2 mm (it catches the peg's fastest approach at
    500 Hz), or half the clearance where that is less. Not more: with 2 mm or 0.5 mm at
    0.5 mm clearance, PhysX's convex-convex contacts held a peg centred within 0.06 mm
    1.7 mm into the entry, on contacts reported touching (the peg chamfer's 45 deg normals)
    at the hole's corners while the walls were 0.25 mm away. Not less: PhysX makes the
    contacts of a wall the peg comes within the contact distance of only after the peg has
    crossed it (a peg sliding 4 mm/s across a 1 mm-clearance hole went 0.4 mm into the
    wall with a 0.2 mm offset, none with 0.4 mm), so the contact distance (twice the
    offset) should span the play: both walls' contacts then stay made."""
    hole_depth: Annotated[float, Field(gt=0.0, lt=PEG_LENGTH)] = DEFAULT_HOLE_DEPTH
    """Depth of the hole, metres (less than the peg's length, or the flange hits the face)."""
    objects: Annotated[tuple[str, ...], Field(min_length=1)] = ("test",)
    """Default hole objects: names or splits (train | test | all)."""
    workspace_x: tuple[Metres, Metres] = (0.40, 0.60)
    """Range of the hole object's x position on the table (world frame, metres)."""
    workspace_y: tuple[Metres, Metres] = (-0.15, 0.15)
    """Range of the hole object's y position on the table (world frame, metres)."""
    yaw_deg: tuple[Degrees, Degrees] = (0.0, 0.0)
    """Range of the object's rotation about the vertical, degrees."""
    tilt_deg: tuple[
        Annotated[float, Field(ge=0.0, le=90.0)], Annotated[float, Field(ge=0.0, le=90.0)]
    ] = (0.0, 0.0)
    """Range of the hole axis' angle from vertical, degrees (6-DoF: 0-50)."""
    init_error: Annotated[
        dict[str, Annotated[float, Field(gt=0.0, le=1.0)]], Field(min_length=1)
    ] = field(default_factory=lambda: {"small": 0.15, "large": 0.30})
    """Named initial peg-tip-to-hole distances, metres (paper: 15 cm small, 30 cm large)."""
    init_cone_deg: Annotated[float, Field(ge=0.0, le=90.0)] = 25.0
    """The peg starts within this angle of the hole's axis, looking at the hole +- init_aim_deg."""
    init_aim_deg: Annotated[float, Field(ge=0.0, le=45.0)] = 5.0
    """Random tilt of the starting tool axis away from the line to the hole, degrees."""
    init_roll_deg: Annotated[float, Field(ge=0.0, le=180.0)] = 45.0
    """Random rotation of the starting tool about its axis, +- degrees."""
    depth_noise_std: Annotated[float, Field(ge=0.0, le=0.05)] = 0.001
    """Gaussian noise on the point cloud, metres (paper: N(0, 1 mm^2))."""
    fine_max_translation: Annotated[float, Field(ge=0.0, le=0.2)] = 0.03
    """Fine dataset: largest random tool offset from the pre-insertion pose, metres. Sized to
    cover what the coarse stage (OAKN) leaves, with margin."""
    fine_max_tilt_deg: Annotated[float, Field(ge=0.0, le=45.0)] = 10.0
    """Fine dataset: largest random tilt of the tool axis, degrees."""
    fine_max_yaw_deg: Annotated[float, Field(ge=0.0, le=180.0)] = 15.0
    """Fine dataset: largest random turn about the tool axis, degrees."""
    camera_width: Annotated[int, Field(ge=16, le=2048)] = 128
    """Wrist camera image size, pixels."""
    camera_height: Annotated[int, Field(ge=16, le=2048)] = 128
    max_episode_steps: Annotated[int, Field(ge=1, le=1_000_000)] = 1500
    """Control steps (20 Hz) before the episode is truncated."""
    source: str = ""

    def __post_init__(self) -> None:
        if self.contact_offset is None:
            offset = min(LOOSE_CONTACT_OFFSET, self.clearance / 2)
            object.__setattr__(self, "contact_offset", offset)

    @property
    def env_id(self) -> str:
        return f"{self.name}-v1"


def square_yaw_play_deg(clearance: float) -> float:
    """The largest turn about its axis at which the square peg's cross-section still fits
    its hole's: h (cos a + sin a) <= the hole's half width, h the peg's half side."""
    h, hole = peg_half_extent("square"), hole_half_extent("square", clearance)
    return float(np.degrees(np.arcsin(min(1.0, hole / (h * np.sqrt(2))))) - 45.0)


def _one_name_as_list(data: dict) -> dict:
    if isinstance(data.get("objects"), str):
        return {**data, "objects": [data["objects"]]}  # one name or split
    return data


def load_task(path: Path) -> TaskConfig:
    cfg = validate_file(TaskConfig, path, TaskConfigError, _one_name_as_list)
    if not (0 <= cfg.peg_chamfer <= 0.25 * peg_half_extent(cfg.peg)):
        raise TaskConfigError(
            path,
            "peg_chamfer",
            f"expected 0 <= peg_chamfer <= {0.25 * peg_half_extent(cfg.peg):.4f} m "
            f"(a quarter of the peg's half width), got {cfg.peg_chamfer}",
        )
    for k in ("workspace_x", "workspace_y", "yaw_deg", "tilt_deg"):
        lo, hi = getattr(cfg, k)
        if lo > hi:
            raise TaskConfigError(path, k, f"expected [min, max] with min <= max, got {[lo, hi]}")
    if cfg.dof != 6 and cfg.tilt_deg != (0.0, 0.0):
        raise TaskConfigError(
            path,
            "tilt_deg",
            f"expected [0, 0] for dof {cfg.dof} (3- and 4-DoF agents keep the peg vertical, "
            f"as the paper's upright holes need), got {list(cfg.tilt_deg)}; or use dof: 6",
        )
    if cfg.dof == 3 and cfg.peg == "square":
        # 3-DoF keeps the peg's yaw: its start roll and the hole's yaw must fit the play.
        off = cfg.init_roll_deg + max(abs(y) for y in cfg.yaw_deg)
        if off > (fits := square_yaw_play_deg(cfg.clearance)):
            raise TaskConfigError(
                path,
                "init_roll_deg",
                f"a square peg under dof 3 keeps its yaw, and enters a hole with "
                f"{cfg.clearance * 1000:g} mm clearance only within {fits:.1f} deg of its "
                f"yaw; init_roll_deg ({cfg.init_roll_deg:g}) plus the largest |yaw_deg| "
                f"({off - cfg.init_roll_deg:g}) is {off:g}: expected at most {fits:.1f}, "
                f"or dof: 4 (x y z and yaw), or peg: round",
            )
    if cfg.contact_offset > cfg.clearance / 2:
        # Measured at 0.5 mm clearance: 0.5 mm and 2 mm offsets stalled centred pegs in the
        # entry (TaskConfig.contact_offset).
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
    dirs = directories or resources.search_dirs("tasks")
    for i, d in enumerate(dirs):
        for p in sorted(Path(d).glob("*.yaml")):
            if p.stem in tasks:
                log.warning("task file %s left out: task '%s' is %s", p, p.stem,
                            tasks[p.stem].source)  # fmt: skip
                continue
            try:
                tasks[p.stem] = load_task(p)
            except TaskConfigError as e:
                if i == 0:
                    raise  # a bundled task must load
                # A bad file in the user folder must not stop the package from importing:
                # it is left out, and asking for it by name gives this error (lookup.py).
                log.warning("task file left out: %s", e)
                INVALID[p.stem] = e
    return tasks


INVALID: dict[str, TaskConfigError] = {}
"""Task files of the user folder that failed to load, by task name."""
