"""Sensor profiles: one small YAML file each in `sensors/` (or any path), chosen per run with
`--sensor NAME`. A profile says how the wrist depth camera errs, how far off the hand-eye
calibration is, how noisy the wrist force/torque sensor is, how far apart the
camera's two imagers are and where the camera is mounted on the tool (`mount`); nothing
downstream may assume one profile's numbers. Unknown fields and profiles are errors that
name them."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field

from cfvs_maniskill import resources
from cfvs_maniskill.errors import FileFieldError
from cfvs_maniskill.robots.mounts import DEFAULT_MOUNT, MOUNTS, Mount
from cfvs_maniskill.sensing.surfaces import MATERIALS
from cfvs_maniskill.validation import STRICT, validate_file

DEFAULT_SENSOR = "ideal"
DEPTH_MODELS = ("iid", "stereo")


def _range(lo: float, hi: float, open_low: bool = False):
    """A number field from lo (excluded if open_low) to hi: the profile file's schema."""
    return Annotated[float, Field(gt=lo) if open_low else Field(ge=lo), Field(le=hi)]


Prob = _range(0.0, 1.0)


class SensorProfileError(FileFieldError):
    """A sensor-profile file that cannot be used."""


@dataclass(frozen=True)
class DepthModel:
    """How the wrist camera's depth errs. Lengths in metres, pixels of the *modelled*
    sensor (its own resolution, not the render's)."""

    __pydantic_config__ = STRICT

    model: Literal["iid", "stereo"] = "iid"
    """iid: Gaussian noise per point (the paper's protocol). stereo: an active-stereo camera
    (noise in disparity, quantisation, edge artefacts, grazing dropouts, range limits)."""
    std: _range(0.0, 0.05) | None = None
    """iid: per-point standard deviation, m (None: the task file's depth_noise_std)."""
    focal_px: _range(0.0, 1e5) = 0.0
    """stereo: the sensor's focal length at its depth resolution, pixels."""
    baseline: _range(0.0, 1.0) = 0.0
    """stereo: distance between the two imagers, m."""
    disparity_noise_px: _range(0.0, 10.0) = 0.0
    """stereo: RMS error of the matched disparity (Intel's "subpixel RMS"), pixels. Axial
    noise is then z^2 * this / (focal_px * baseline): it grows with the square of depth."""
    disparity_step_px: _range(0.0, 1.0) = 0.0
    """stereo: disparity quantisation, pixels (0: none)."""
    depth_unit: _range(0.0, 0.01) = 0.0
    """Reported depth quantisation, m (0: none)."""
    lateral_noise_px: _range(0.0, 10.0) = 0.0
    """Gaussian jitter of where a pixel's ray points, sensor pixels."""
    min_range: _range(0.0, 10.0) = 0.0
    """No return nearer than this, m."""
    max_range: _range(0.0, 100.0, open_low=True) = 10.0
    """No return further than this, m."""
    edge_jump: _range(0.0, 1.0) = 0.005
    """A pixel whose neighbour's depth differs by more than this (m), or that borders a
    pixel with no return, is at a depth discontinuity."""
    edge_dropout: Prob = 0.0
    """Probability that a pixel at a discontinuity returns nothing (stereo occlusion,
    failed left-right check)."""
    edge_flying: Prob = 0.0
    """Probability that a pixel at a discontinuity returns a depth between the near and the
    far side (a "flying pixel": the matching window straddles the edge)."""
    max_incidence_deg: _range(0.0, 90.0) = 90.0
    """No return where the surface is seen more obliquely than this (ray to normal)."""
    occlusion: bool = False
    """stereo: no return where the right imager (`baseline` along the image's x) cannot see
    the point: the one-sided band beside every near edge that a stereo pair cannot match."""
    imager_noise: _range(0.0, 1.0) = 0.0
    """stereo: the imagers' noise, fraction of full scale. With it, matching follows each
    surface's texture signal (albedo x texture contrast x cos incidence, plus the projector's
    pattern): disparity noise and dropouts grow as that signal falls towards this noise
    (`texture_*`). 0: every surface matches as a well-textured target."""
    projector: _range(0.0, 1.0) = 0.0
    """stereo: contrast of a projected pattern (active stereo), as a texture contrast that
    every surface gets times its albedo; 0: passive stereo (no projector)."""
    texture_noise_snr: _range(0.0, 100.0, open_low=True) = 0.74
    """Texture signal-to-imager-noise ratio at which the disparity noise is sqrt(2) times
    `disparity_noise_px`: noise = that * sqrt(1 + (texture_noise_snr / snr)^2)."""
    texture_fill_snr: _range(0.0, 100.0, open_low=True) = 0.243
    """Signal-to-noise ratio at which half the pixels match: fill = Phi(ln(snr /
    texture_fill_snr) / texture_fill_spread), drawn once per episode and pixel."""
    texture_fill_spread: _range(0.0, 10.0, open_low=True) = 0.44
    """Spread of the fill's fall (log signal-to-noise)."""
    fixed_pattern: Prob = 0.0
    """Share of the disparity noise's variance that is fixed for the episode (the same at a
    pixel in every observation); the rest is drawn anew per observation."""
    depth_scale_error: _range(0.0, 0.5) = 0.0
    """Per episode, the reported depth is (1 + s) times the true one, s uniform in +- this
    (the absolute accuracy of an untared stereo camera)."""
    depth_offset_error: _range(0.0, 0.1) = 0.0
    """Per episode, an offset uniform in +- this (m) is added to every depth."""
    focal_error: _range(0.0, 0.2) = 0.0
    """Per episode, the reported focal length is off the true one by a factor uniform in
    1 +- this: the cloud is formed with the reported one."""
    principal_point_error_px: _range(0.0, 100.0) = 0.0
    """Per episode, the reported principal point is off the true one by up to this many
    sensor pixels per axis (uniform)."""
    fov_deg: tuple[_range(1.0, 170.0), _range(1.0, 170.0)] | None = None
    """The depth camera's field of view, horizontal x vertical degrees; the wrist camera is
    rendered at the task's angular resolution over it. None: the task's 70 x 70 deg."""


@dataclass(frozen=True)
class HandEye:
    """The camera mount's calibration error: a rigid transform of this size, in a random
    direction drawn per episode; the robot does not know it."""

    __pydantic_config__ = STRICT

    translation: _range(0.0, 0.1) = 0.0
    """m."""
    rotation_deg: _range(0.0, 45.0) = 0.0
    """degrees."""


@dataclass(frozen=True)
class Wrench:
    """The wrist force/torque sensor's errors (per axis, flange frame)."""

    __pydantic_config__ = STRICT

    force_noise: _range(0.0, 1000.0) = 0.0
    """N, standard deviation per reading."""
    torque_noise: _range(0.0, 100.0) = 0.0
    """N m, standard deviation per reading."""
    force_bias: _range(0.0, 1000.0) = 0.0
    """N, standard deviation of an offset fixed for the episode (the sensor's zero drifts;
    a cell tares it out before contact, as the force-guided insertion does)."""
    torque_bias: _range(0.0, 100.0) = 0.0
    """N m, as force_bias."""


@dataclass(frozen=True)
class Imager:
    """The wrist camera's image pair, for image-based agents (KOVIS sees both imagers of a
    stereo camera, as its authors did with a RealSense D435's infrared pair)."""

    __pydantic_config__ = STRICT

    stereo_baseline: _range(0.0, 1.0, open_low=True) = 0.05
    """Distance from the wrist camera (the left imager) to the right imager, m. Default: the
    RealSense D435's 50 mm (Intel D400 datasheet), the camera KOVIS was built with."""


@dataclass(frozen=True)
class Surfaces:
    """What the scene's surfaces look like to the stereo matcher (sensing/surfaces.py)."""

    __pydantic_config__ = STRICT

    part_material: str | None = None
    """Every hole object is made of this material (a name in sensing/surfaces.py), whatever
    its file says; None: each object's own `material` / `texture`."""


@dataclass(frozen=True)
class CameraMount:
    """Where the wrist camera sits on the tool (robots/mounts.py): a named mount, or this
    profile's own bracket (`position` and `aim` in the flange frame, m, and its `source`)."""

    __pydantic_config__ = STRICT

    name: str = DEFAULT_MOUNT
    position: tuple[float, float, float] | None = None
    aim: tuple[float, float, float] | None = None
    source: str = ""

    def resolve(self, path: Path | str = "<profile>") -> Mount:
        """The mount this section names or describes; errors name the field."""
        own = [k for k in ("position", "aim", "source") if getattr(self, k)]
        if self.name in MOUNTS:
            if own:
                raise SensorProfileError(
                    path,
                    f"mount.{own[0]}",
                    f"{self.name!r} is a named mount with its own "
                    "geometry; give yours another name",
                )
            return MOUNTS[self.name]
        if not own:
            raise SensorProfileError(
                path,
                "mount.name",
                f"one of {', '.join(MOUNTS)}, or a mount of your own with position, aim and "
                f"source; got {self.name!r}",
            )
        for k in ("position", "aim", "source"):
            if not getattr(self, k):
                raise SensorProfileError(
                    path, f"mount.{k}", "a mount of your own needs position, aim and source"
                )
        mount = Mount(self.name, self.position, self.aim, self.source)
        if problem := mount.check():
            raise SensorProfileError(path, f"mount.{problem[0]}", problem[1])
        return mount


@dataclass(frozen=True)
class SensorProfile:
    """A profile file's schema (validation.py) and the profile it gives."""

    __pydantic_config__ = STRICT
    NOT_IN_FILE = ("name", "source")  # from the file's name and place, not its text

    name: str
    description: str = ""
    sources: tuple[str, ...] = ()
    """Where each number comes from (datasheets, papers; "assumed" where none)."""
    depth: DepthModel = field(default_factory=DepthModel)
    hand_eye: HandEye = field(default_factory=HandEye)
    wrench: Wrench = field(default_factory=Wrench)
    imager: Imager = field(default_factory=Imager)
    surfaces: Surfaces = field(default_factory=Surfaces)
    mount: CameraMount = field(default_factory=CameraMount)
    source: str = ""
    """The file it was read from."""

    @property
    def camera_mount(self) -> Mount:
        return self.mount.resolve(self.source or self.name)


def with_mount(profile: SensorProfile, mount: str | None) -> SensorProfile:
    """`profile` with the named mount `mount` in place of its own (None: as it is)."""
    if mount is None:
        return profile
    section = CameraMount(name=mount)
    section.resolve("the env's camera_mount")  # an unknown name: an error naming mount.name
    return dataclasses.replace(profile, mount=section)


_SECTIONS = ("depth", "hand_eye", "wrench", "imager", "surfaces", "mount")


def _empty_sections_default(data: dict) -> dict:
    """Empty sections take their defaults; `mount: NAME` is short for `mount: {name: NAME}`."""
    data = {k: v for k, v in data.items() if not (k in _SECTIONS and v is None)}
    if isinstance(data.get("mount"), str):
        data["mount"] = {"name": data["mount"]}
    return data


def load_profile_file(path: Path) -> SensorProfile:
    profile = validate_file(SensorProfile, path, SensorProfileError, _empty_sections_default)
    d = profile.depth
    for k in ("focal_px", "baseline"):
        if d.model == "stereo" and getattr(d, k) <= 0:
            raise SensorProfileError(
                path, f"depth.{k}", "a stereo model needs focal_px > 0 and baseline > 0"
            )
    if d.min_range >= d.max_range:
        raise SensorProfileError(path, "depth.min_range", "expected min_range < max_range")
    if d.edge_dropout + d.edge_flying > 1:
        raise SensorProfileError(path, "depth.edge_flying", "edge_dropout + edge_flying > 1")
    material = profile.surfaces.part_material
    if material is not None and material not in MATERIALS:
        raise SensorProfileError(
            path, "surfaces.part_material", f"one of {', '.join(MATERIALS)}, got {material!r}"
        )
    profile.mount.resolve(path)  # a bad mount is the file's error, not the env's
    return profile


def available_profiles() -> list[str]:
    """Profile names: the bundled ones and the user folder's (resources.py)."""
    names = {p.stem for d in resources.search_dirs("sensors") for p in d.glob("*.yaml")}
    return sorted(names)


def load_profile(name_or_path: str | SensorProfile | None) -> SensorProfile:
    """A profile by name (`sensors/<name>.yaml`, bundled or the user folder's) or by file
    path; None: the default."""
    if isinstance(name_or_path, SensorProfile):
        return name_or_path
    name = name_or_path or DEFAULT_SENSOR
    path = Path(name)
    if path.suffix in (".yaml", ".yml") or path.is_file():
        if not path.is_file():
            raise SensorProfileError(path, "<file>", "no such sensor profile file")
        return load_profile_file(path)
    candidate = resources.find("sensors", name)
    if candidate is None or not candidate.is_file():
        where = " and ".join(str(d) for d in resources.search_dirs("sensors"))
        raise ValueError(
            f"unknown sensor profile '{name}'; available: {', '.join(available_profiles())} "
            f"(files in {where}), or a path to a .yaml profile"
        )
    return load_profile_file(candidate)
