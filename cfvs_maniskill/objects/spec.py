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
from typing import Any

import yaml

from cfvs_maniskill.constants import PEG_PROFILES
from cfvs_maniskill.errors import FileFieldError

SPLITS = ("train", "test")
TOP_KEYS = ("name", "split", "hole", "body", "hole_at", "hole_frame", "color")
HOLE_FRAME_KEYS = ("origin", "axis")
BODY_FIELDS: dict[str, dict[str, str]] = {
    # kind -> field -> expected type ("size3", "pos", "int>=3", "path", "pos_opt")
    "box": {"size": "size3"},
    "cylinder": {"radius": "pos", "height": "pos"},
    "prism": {"sides": "int>=3", "radius": "pos", "height": "pos"},
    "mesh": {"file": "path", "scale": "pos_opt"},
}
MESH_SUFFIXES = (".obj", ".stl", ".ply")
_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


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


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _number_list(file: Path, fld: str, v: Any, n: int, positive: bool) -> tuple[float, ...]:
    what = f"a list of {n} {'positive ' if positive else ''}numbers (metres)"
    if not isinstance(v, list | tuple) or len(v) != n or not all(_is_number(x) for x in v):
        raise HoleSpecError(file, fld, f"expected {what}, got {v!r}")
    if positive and any(x <= 0 for x in v):
        raise HoleSpecError(file, fld, f"expected {what}, got {v!r} (sizes must be > 0)")
    return tuple(float(x) for x in v)


def _check_body(file: Path, body: Any) -> tuple[str, dict[str, Any]]:
    kinds = ", ".join(BODY_FIELDS)
    if not isinstance(body, dict) or not body:
        raise HoleSpecError(file, "body", f"expected a mapping with exactly one of: {kinds}")
    unknown = [k for k in body if k not in BODY_FIELDS]
    if unknown:
        raise HoleSpecError(
            file, f"body.{unknown[0]}", f"unknown body kind; expected exactly one of: {kinds}"
        )
    if len(body) != 1:
        raise HoleSpecError(
            file, "body", f"has {len(body)} body kinds ({', '.join(body)}); expected exactly one"
        )
    kind, params = next(iter(body.items()))
    fields = BODY_FIELDS[kind]
    if not isinstance(params, dict):
        raise HoleSpecError(
            file, f"body.{kind}", f"expected a mapping with fields {', '.join(fields)}"
        )
    for k in params:
        if k not in fields:
            raise HoleSpecError(
                file, f"body.{kind}.{k}", f"unknown field; expected one of: {', '.join(fields)}"
            )
    out: dict[str, Any] = {}
    for name, kind_of in fields.items():
        fld = f"body.{kind}.{name}"
        if name not in params:
            if kind_of == "pos_opt":
                out[name] = 1.0
                continue
            raise HoleSpecError(file, fld, "missing; required for a " + kind + " body")
        v = params[name]
        if kind_of == "size3":
            out[name] = _number_list(file, fld, v, 3, positive=True)
        elif kind_of in ("pos", "pos_opt"):
            if not _is_number(v) or v <= 0:
                raise HoleSpecError(file, fld, f"expected a positive number, got {v!r}")
            out[name] = float(v)
        elif kind_of == "int>=3":
            if not isinstance(v, int) or isinstance(v, bool) or v < 3:
                raise HoleSpecError(file, fld, f"expected an integer >= 3, got {v!r}")
            out[name] = v
        elif kind_of == "path":
            if not isinstance(v, str) or not v:
                raise HoleSpecError(file, fld, f"expected a file name (string), got {v!r}")
            if Path(v).suffix.lower() not in MESH_SUFFIXES:
                raise HoleSpecError(
                    file, fld, f"expected an {'/'.join(MESH_SUFFIXES)} file, got {v!r}"
                )
            path = (file.parent / v).resolve()
            if not path.is_file():
                raise HoleSpecError(file, fld, f"mesh file not found: {path}")
            out[name] = v
    return kind, out


def _check_hole_frame(file: Path, v: Any):
    keys = ", ".join(HOLE_FRAME_KEYS)
    if not isinstance(v, dict):
        raise HoleSpecError(file, "hole_frame", f"expected a mapping with {keys}, got {v!r}")
    for k in v:
        if k not in HOLE_FRAME_KEYS:
            raise HoleSpecError(file, f"hole_frame.{k}", f"unknown field; expected {keys}")
    for k in HOLE_FRAME_KEYS:
        if k not in v:
            raise HoleSpecError(file, f"hole_frame.{k}", f"missing; hole_frame needs {keys}")
    origin = _number_list(file, "hole_frame.origin", v["origin"], 3, positive=False)
    axis = _number_list(file, "hole_frame.axis", v["axis"], 3, positive=False)
    norm = sum(a * a for a in axis) ** 0.5
    if norm < 1e-9:
        raise HoleSpecError(
            file, "hole_frame.axis", f"expected a non-zero direction (out of the part), got {axis}"
        )
    return origin, tuple(a / norm for a in axis)


def parse_spec(data: Any, file: Path, raw_text: str = "") -> HoleSpec:
    """Validate an already-parsed YAML document. Raises HoleSpecError."""
    if not isinstance(data, dict):
        raise HoleSpecError(file, "<top>", f"expected a mapping of {', '.join(TOP_KEYS)}")
    for k in data:
        if k not in TOP_KEYS:
            raise HoleSpecError(
                file, str(k), f"unknown key; expected one of: {', '.join(TOP_KEYS)}"
            )
    name = data.get("name", file.stem)
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise HoleSpecError(
            file, "name", f"expected a name of letters, digits, _ . -, got {name!r}"
        )
    split = data.get("split", "test")
    if split not in SPLITS:
        raise HoleSpecError(file, "split", f"expected one of {', '.join(SPLITS)}, got {split!r}")
    hole = data.get("hole", list(PEG_PROFILES))
    if isinstance(hole, str):
        hole = [hole]
    if (
        not isinstance(hole, list)
        or not hole
        or not all(isinstance(h, str) and h in PEG_PROFILES for h in hole)
    ):
        raise HoleSpecError(
            file, "hole", f"expected a non-empty list of {', '.join(PEG_PROFILES)}, got {hole!r}"
        )
    if "body" not in data:
        raise HoleSpecError(file, "body", "missing; expected one of " + ", ".join(BODY_FIELDS))
    kind, body = _check_body(file, data["body"])
    hole_at = _number_list(file, "hole_at", data.get("hole_at", [0.0, 0.0]), 2, positive=False)
    hole_frame = None
    if "hole_frame" in data:
        if "hole_at" in data:
            raise HoleSpecError(
                file,
                "hole_frame",
                "give either hole_at (a point on the top face) or hole_frame (a point and an "
                "axis on any planar face), not both",
            )
        hole_frame = _check_hole_frame(file, data["hole_frame"])
    color = data.get("color", [0.6, 0.6, 0.65])
    if (
        not isinstance(color, list | tuple)
        or len(color) not in (3, 4)
        or not all(_is_number(c) and 0 <= c <= 1 for c in color)
    ):
        raise HoleSpecError(file, "color", f"expected [r, g, b] with values in 0..1, got {color!r}")
    return HoleSpec(
        name=name,
        split=split,
        hole=tuple(dict.fromkeys(hole)),
        body_kind=kind,
        body=body,
        hole_at=(hole_at[0], hole_at[1]),
        color=tuple(float(c) for c in color),
        source=file,
        raw_text=raw_text,
        hole_frame=hole_frame,
    )


def load_spec(path: Path | str) -> HoleSpec:
    """Read one YAML hole-object file. Raises HoleSpecError naming the file and field."""
    path = Path(path).resolve()
    try:
        text = path.read_text()
    except OSError as e:
        raise HoleSpecError(path, "<file>", f"cannot read: {e.strerror}") from e
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark else ""
        raise HoleSpecError(path, "<yaml>", f"not valid YAML{where}: {e}") from e
    return parse_spec(data, path, text)
