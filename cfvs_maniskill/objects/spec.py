"""Read and validate one hole-object file (`assets/holes/<name>.yaml`).

The contract (DESIGN.md):

    name: pentagonal_prism        # unique id; defaults to the file stem
    split: test                   # train | test  (default: test, never trained on)
    hole: [round, square]         # peg profiles it can host (default: both)
    body:                         # exactly one of:
      box:      {size: [0.13, 0.13, 0.07]}             # metres, x y z
      cylinder: {radius: 0.065, height: 0.07}
      prism:    {sides: 5, radius: 0.07, height: 0.07}  # regular polygon, circumradius
      mesh:     {file: bracket.obj, scale: 0.001}       # OBJ/STL/PLY, relative to the yaml
    hole_at: [0.0, 0.0]           # hole centre on the top face, metres from its centre
    hole_frame:                   # or (instead of hole_at): the hole on any planar face
      origin: [45.0, 0.0, 50.0]   #   centre of the opening, in the body's own frame
      axis: [0.0, 0.0, 1.0]       #   out of the part: the face's outward normal
    color: [0.6, 0.6, 0.65]
    material: plain               # what a stereo camera sees of it: plain | machined | wood |
                                  #   printed (sensing/surfaces.py; default plain)
    texture: 0.01                 # or its texture contrast itself (0-1), overriding material

`hole_frame` is for real parts whose global top is a boss or a curved surface: the hole may
open on any planar face, at any angle. Its origin is in the mesh file's own coordinates and
units (`scale` applies to it as to the mesh), so it can be read off the CAD model; for
primitive bodies it is in the body frame (metres, bottom centre). The body is turned so that
`axis` points up, which makes the hole frame's z the body's +z as with `hole_at`.

Every error names the file, the field and what was expected. Geometry checks that need the
mesh (watertight, room for the hole) live in `objects.build`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field

from cfvs_maniskill.constants import PEG_PROFILES
from cfvs_maniskill.errors import FileFieldError
from cfvs_maniskill.sensing.surfaces import DEFAULT_PART_MATERIAL, MATERIALS, contrast_of
from cfvs_maniskill.validation import STRICT, parse_yaml, read_text, validate

SPLITS = ("train", "test")
BODY_KINDS = ("box", "cylinder", "prism", "mesh")
MESH_SUFFIXES = (".obj", ".stl", ".ply")
_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")

Size = Annotated[float, Field(gt=0.0, le=2.0)]
"""A body dimension, metres: positive, and a part a UR5 can work on (at most 2 m)."""
Coord = Annotated[float, Field(ge=-1e4, le=1e4)]
"""A coordinate in the body's (or the mesh file's own) units."""
Unit = Annotated[float, Field(ge=0.0, le=1.0)]


# The file's schema (validation.py): one dataclass per mapping in it.
@dataclass(frozen=True)
class BoxBody:
    __pydantic_config__ = STRICT
    size: tuple[Size, Size, Size]
    """x y z, metres."""


@dataclass(frozen=True)
class CylinderBody:
    __pydantic_config__ = STRICT
    radius: Size
    height: Size


@dataclass(frozen=True)
class PrismBody:
    __pydantic_config__ = STRICT
    sides: Annotated[int, Field(ge=3, le=64)]
    radius: Size
    """Circumradius, metres."""
    height: Size


@dataclass(frozen=True)
class MeshBody:
    __pydantic_config__ = STRICT
    file: Annotated[str, Field(min_length=1)]
    """OBJ / STL / PLY, relative to the YAML file."""
    scale: Annotated[float, Field(gt=0.0, le=1e3)] = 1.0


@dataclass(frozen=True)
class BodyFile:
    __pydantic_config__ = STRICT
    box: BoxBody | None = None
    cylinder: CylinderBody | None = None
    prism: PrismBody | None = None
    mesh: MeshBody | None = None


@dataclass(frozen=True)
class HoleFrameFile:
    __pydantic_config__ = STRICT
    origin: tuple[Coord, Coord, Coord]
    axis: tuple[Coord, Coord, Coord]


@dataclass(frozen=True)
class HoleFile:
    """A hole-object file as written (the contract above)."""

    __pydantic_config__ = STRICT
    body: BodyFile
    name: str | None = None
    split: Literal["train", "test"] = "test"
    hole: Annotated[tuple[Literal["round", "square"], ...], Field(min_length=1)] = PEG_PROFILES
    hole_at: tuple[Coord, Coord] | None = None
    hole_frame: HoleFrameFile | None = None
    color: Annotated[tuple[Unit, ...], Field(min_length=3, max_length=4)] = (0.6, 0.6, 0.65)
    material: str = DEFAULT_PART_MATERIAL
    texture: Unit | None = None


class HoleSpecError(FileFieldError):
    """A hole-object file that cannot be used. `str()` names file, field and expectation."""


@dataclass(frozen=True)
class HoleSpec:
    """A validated hole-object file. Lengths in metres; the hole axis is the body's +z."""

    name: str
    split: str
    hole: tuple[str, ...]
    body_kind: str
    body: dict[str, Any]
    hole_at: tuple[float, float]
    color: tuple[float, ...]
    source: Path
    raw_text: str = field(repr=False, default="")
    hole_frame: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    """(origin, unit axis) of the hole's opening in the body's own frame, or None: the hole
    opens on the top face at hole_at."""
    material: str = DEFAULT_PART_MATERIAL
    texture: float | None = None
    """Texture contrast for the stereo matcher (None: the material's; sensing/surfaces.py)."""

    @property
    def texture_contrast(self) -> float:
        return contrast_of(self.material, self.texture)

    @property
    def mesh_file(self) -> Path | None:
        if self.body_kind != "mesh":
            return None
        return (self.source.parent / self.body["file"]).resolve()

    def describe_body(self) -> str:
        b = self.body
        if self.body_kind == "box":
            return "box " + " x ".join(f"{v * 1000:g}" for v in b["size"]) + " mm"
        if self.body_kind == "cylinder":
            return f"cylinder r {b['radius'] * 1000:g} h {b['height'] * 1000:g} mm"
        if self.body_kind == "prism":
            return f"{b['sides']}-prism r {b['radius'] * 1000:g} h {b['height'] * 1000:g} mm"
        return f"mesh {b['file']} x{b['scale']:g}"


def parse_spec(data: Any, file: Path, raw_text: str = "") -> HoleSpec:
    """Validate an already-parsed YAML document. Raises HoleSpecError."""
    if not isinstance(data, dict):
        raise HoleSpecError(file, "<top>", "expected a mapping of hole-object fields")
    if isinstance(data.get("hole"), str):
        data = {**data, "hole": [data["hole"]]}  # one profile
    body = data.get("body")
    if isinstance(body, dict):
        unknown = [k for k in body if k not in BODY_KINDS]
        if unknown:
            raise HoleSpecError(
                file,
                f"body.{unknown[0]}",
                f"unknown body kind; expected exactly one of {', '.join(BODY_KINDS)}",
            )
    f = validate(HoleFile, data, file, HoleSpecError)
    kinds = [k for k in BODY_KINDS if getattr(f.body, k) is not None]
    if len(kinds) != 1:
        raise HoleSpecError(
            file,
            "body",
            f"has {len(kinds)} body kinds ({', '.join(kinds)}); "
            f"expected exactly one of {', '.join(BODY_KINDS)}",
        )
    kind = kinds[0]
    params = dict(vars(getattr(f.body, kind)))
    if kind == "mesh":
        if Path(params["file"]).suffix.lower() not in MESH_SUFFIXES:
            raise HoleSpecError(
                file,
                "body.mesh.file",
                f"expected an {'/'.join(MESH_SUFFIXES)} file, got {params['file']!r}",
            )
        if not (file.parent / params["file"]).resolve().is_file():
            raise HoleSpecError(
                file,
                "body.mesh.file",
                f"mesh file not found: {(file.parent / params['file']).resolve()}",
            )
    if f.material not in MATERIALS:
        raise HoleSpecError(file, "material", f"one of {', '.join(MATERIALS)}, got {f.material!r}")
    name = file.stem if f.name is None else f.name
    if not _NAME_RE.match(name):
        raise HoleSpecError(
            file, "name", f"expected a name of letters, digits, _ . -, got {name!r}"
        )
    hole_frame = None
    if f.hole_frame is not None:
        if f.hole_at is not None:
            raise HoleSpecError(
                file,
                "hole_frame",
                "give either hole_at (a point on the top face) or hole_frame (a point and an "
                "axis on any planar face), not both",
            )
        axis = f.hole_frame.axis
        norm = sum(a * a for a in axis) ** 0.5
        if norm < 1e-9:
            raise HoleSpecError(
                file,
                "hole_frame.axis",
                f"expected a non-zero direction (out of the part), got {list(axis)}",
            )
        hole_frame = (f.hole_frame.origin, tuple(a / norm for a in axis))
    return HoleSpec(
        name=name,
        split=f.split,
        hole=tuple(dict.fromkeys(f.hole)),
        body_kind=kind,
        body=params,
        hole_at=f.hole_at or (0.0, 0.0),
        color=f.color,
        source=file,
        raw_text=raw_text,
        hole_frame=hole_frame,
        material=f.material,
        texture=f.texture,
    )


def load_spec(path: Path | str) -> HoleSpec:
    """Read one YAML hole-object file. Raises HoleSpecError naming the file and field."""
    try:
        path = Path(path).resolve()
    except (OSError, RuntimeError) as e:  # a symlink loop: RuntimeError before Python 3.13
        raise HoleSpecError(path, "<file>", f"cannot resolve the path: {e}") from None
    text = read_text(path, HoleSpecError)
    return parse_spec(parse_yaml(text, path, HoleSpecError), path, text)  # bounded YAML
