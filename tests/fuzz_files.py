"""Fuzz the files a user writes: every field of every file kind (task file, sensor profile,
hole object) set to a wrong type, NaN, a negative number, a huge number, or left out.
Each case must give a named error (the file and that field) or, where the value is one
the field allows (a negative workspace y, a left-out optional key), load; none may raise
anything else. `python -m tests.fuzz_files` rewrites the table in tests/FUZZ.md.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import sys
import tempfile
import typing
from collections.abc import Callable
from pathlib import Path

import yaml

from cfvs_maniskill import resources
from cfvs_maniskill.envs.task_config import TaskConfig, load_task
from cfvs_maniskill.errors import FileFieldError
from cfvs_maniskill.objects.spec import HoleFile, load_spec
from cfvs_maniskill.sensing.profile import SensorProfile, load_profile_file
from cfvs_maniskill.validation import type_at


def _wrong_type(field_type) -> object:
    """A number where text (or a list of it) is expected, else text."""
    args = typing.get_args(field_type) if typing.get_origin(field_type) is tuple else ()
    text = field_type is str or (args and args[0] is str)
    return 7 if text else "seven"


BAD = {
    "wrong type": _wrong_type,
    "NaN": lambda _: math.nan,
    "negative": lambda _: -1.0,
    "huge": lambda _: 1e300,
    "missing": None,
}
"""Bad-value kinds: a value for the field's type, or None to leave the key out."""

NEGATIVE_ALLOWED = {"workspace_y", "yaw_deg", "hole_at", "hole_frame.origin", "hole_frame.axis",
                    "mount.position", "mount.aim"}  # fmt: skip
"""Fields where a negative number is a valid value (positions, angles, directions)."""

BASE_HOLE = {
    "name": "fuzz_block",
    "split": "test",
    "hole": ["round", "square"],
    "body": {"box": {"size": [0.13, 0.13, 0.07]}},
    "hole_at": [0.0, 0.0],
    "color": [0.5, 0.5, 0.5],
}
BODIES = {
    "cylinder": {"radius": 0.07, "height": 0.07},
    "prism": {"sides": 6, "radius": 0.07, "height": 0.07},
    "mesh": {"file": "part.stl", "scale": 0.001},
}


@dataclasses.dataclass
class Kind:
    name: str
    base: dict
    schema: type
    load: Callable[[Path], object]
    files: Callable[[Path], None] = lambda _: None
    """Writes any file the base needs beside it (a mesh)."""


def _mesh(folder: Path) -> None:
    import trimesh

    trimesh.creation.box([130.0, 130.0, 70.0]).export(folder / "part.stl")


def kinds() -> list[Kind]:
    task = yaml.safe_load((resources.bundled("tasks") / "PegInsert6DoF.yaml").read_text())
    sensor = yaml.safe_load((resources.bundled("sensors") / "realistic.yaml").read_text())
    out = [
        Kind("task file", task, TaskConfig, load_task),
        Kind("sensor profile", sensor, SensorProfile, load_profile_file),
        Kind("hole object", BASE_HOLE, HoleFile, load_spec),
    ]
    for body, params in BODIES.items():
        base = {**BASE_HOLE, "body": {body: params}}
        out.append(Kind(f"hole object ({body})", base, HoleFile, load_spec, _mesh))
    framed = {k: v for k, v in BASE_HOLE.items() if k != "hole_at"}
    framed["hole_frame"] = {"origin": [0.0, 0.0, 0.07], "axis": [0.0, 0.0, 1.0]}
    out.append(Kind("hole object (hole_frame)", framed, HoleFile, load_spec))
    return out


def _leaves(data: dict, prefix: tuple = ()) -> list[tuple]:
    """Paths to every field of a file (a mapping's fields, not list items)."""
    out = []
    for k, v in data.items():
        out.append((*prefix, k))
        if isinstance(v, dict) and k not in ("init_error",):
            out += _leaves(v, (*prefix, k))
    return out


def _fields(kind: Kind) -> list[tuple]:
    """Every field of the base file, and every schema field the base leaves out."""
    paths = _leaves(kind.base)
    for path in list(paths) + [()]:
        tp = type_at(kind.schema, path)
        if dataclasses.is_dataclass(tp):
            hidden = getattr(tp, "NOT_IN_FILE", ())
            for f in dataclasses.fields(tp):
                if f.name not in hidden and (*path, f.name) not in paths:
                    if path[:1] == ("body",) or path == ("body",):
                        continue  # other body kinds: their own Kind covers them
                    paths.append((*path, f.name))
    return paths


def _set(data: dict, path: tuple, value) -> dict:
    data = copy.deepcopy(data)
    d = data
    for k in path[:-1]:
        d = d.setdefault(k, {})
    if value is None:
        d.pop(path[-1], None)
    else:
        d[path[-1]] = value
    return data


def run_case(kind: Kind, path: tuple, bad: str) -> tuple[str, str]:
    """(outcome, message): outcome "named" (an error naming the file and the field or a
    field inside it), "loaded", "misnamed" (an error naming another field) or "crash"."""
    field_type = type_at(kind.schema, path)
    make = BAD[bad]
    value = None if make is None else make(field_type)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        kind.files(folder)
        file = folder / "fuzz.yaml"
        file.write_text(yaml.safe_dump(_set(kind.base, path, value)))
        try:
            kind.load(file)
        except FileFieldError as e:
            dotted = ".".join(str(p) for p in path)
            named = e.file.endswith("fuzz.yaml") and (
                e.field == dotted or e.field.startswith(dotted + ".") or e.field == "body"
            )
            return ("named" if named else "misnamed"), str(e).split(": ", 1)[1]
        except Exception as e:  # the failure this test exists to find
            return "crash", f"{type(e).__name__}: {e}"
    return "loaded", ""


def expected(path: tuple, bad: str, kind: Kind) -> set[str]:
    """The outcomes that are right for a case."""
    dotted = ".".join(str(p) for p in path)
    if bad in ("wrong type", "NaN", "huge"):
        return {"named"}
    if bad == "negative":
        if dotted in NEGATIVE_ALLOWED:
            return {"named", "loaded"}
        field_type = type_at(kind.schema, path)
        return {"named"} if field_type is not str else {"named", "loaded"}
    return {"named", "loaded"}  # missing: an error for a required field, else the default


def cases() -> list[tuple[Kind, tuple, str]]:
    return [(k, p, b) for k in kinds() for p in _fields(k) for b in BAD]


def table() -> str:
    rows = ["| file kind | field | " + " | ".join(BAD) + " |", "|---|---|" + "---|" * len(BAD)]
    counts: dict[str, int] = {}
    for k in kinds():
        for p in _fields(k):
            cells = []
            for b in BAD:
                outcome, _ = run_case(k, p, b)
                counts[outcome] = counts.get(outcome, 0) + 1
                cells.append(outcome)
            rows.append(f"| {k.name} | `{'.'.join(map(str, p))}` | " + " | ".join(cells) + " |")
    total = ", ".join(f"{n} {o}" for o, n in sorted(counts.items()))
    return "\n".join(rows) + f"\n\n{sum(counts.values())} cases: {total}."


def main() -> int:
    from cfvs_maniskill.report.tables import replace_marked

    doc = Path(__file__).resolve().parent / "FUZZ.md"
    doc.write_text(replace_marked(doc.read_text(), "fuzz", table(), str(doc)))
    print(f"wrote the fuzz table into {doc}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
