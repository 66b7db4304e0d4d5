"""The one validation layer for the files a user writes: task files, sensor profiles and hole
objects. Each file kind is a dataclass whose fields carry their types and ranges; a file's
YAML is checked against it by pydantic v2 in strict JSON mode (YAML's own types: no string
read as a number, no 1 read as true, no 128.5 read as 128, no NaN or infinity, no unknown
key), and the first problem becomes the project's one error shape: file, field, what was
expected (errors.FileFieldError). Rules between fields stay with each loader."""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import types
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import yaml
from pydantic import ConfigDict, TypeAdapter, ValidationError

from cfvs_maniskill.errors import FileFieldError

T = TypeVar("T")

MAX_FILE_BYTES = 1 << 20
"""A user file larger than this (1 MiB) is refused before it is parsed: the largest real one
(a hole file with a long description) is a few kB."""
MAX_NODES = 10_000
"""Values (mappings, lists, scalars) a file may hold; the largest real one holds about 100."""
MAX_DEPTH = 16
"""How deep mappings and lists may nest; real files nest 3 deep."""


class _BoundedLoader(yaml.SafeLoader):
    """PyYAML's safe loader that refuses what no user file needs and what makes a small file
    expand without bound: anchors and aliases (an alias bomb of 10 lines is 9^9 values),
    nesting past MAX_DEPTH (PyYAML recurses per level), more than MAX_NODES values."""

    def __init__(self, stream):
        super().__init__(stream)
        self.depth = self.nodes = 0

    def compose_node(self, parent, index):
        mark = self.peek_event().start_mark
        if self.check_event(yaml.AliasEvent) or getattr(self.peek_event(), "anchor", None):
            raise _TooBig(
                mark, "anchors and aliases (&name, *name) are not read: write the value out"
            )
        self.depth += 1
        self.nodes += 1
        if self.depth > MAX_DEPTH:
            raise _TooBig(mark, f"nested more than {MAX_DEPTH} levels deep")
        if self.nodes > MAX_NODES:
            raise _TooBig(mark, f"more than {MAX_NODES} values")
        try:
            return super().compose_node(parent, index)
        finally:
            self.depth -= 1


class _TooBig(yaml.YAMLError):
    def __init__(self, mark, what: str):
        super().__init__(f"{what} (line {mark.line + 1})")


def read_yaml(path: Path | str, error: type[FileFieldError] = FileFieldError) -> Any:
    """A user's YAML file, bounded before anything walks it (size, nesting, values, no
    aliases); any problem is `error(file, "<file>" or "<top>", what is wrong)`."""
    return parse_yaml(read_text(path, error), path, error)


def read_text(path: Path | str, error: type[FileFieldError] = FileFieldError) -> str:
    """A user's text file of at most MAX_FILE_BYTES, as UTF-8; else `error` naming it."""
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise error(path, "<file>", f"{size} bytes; a file of at most {MAX_FILE_BYTES} bytes")
        return path.read_bytes().decode()
    except OSError as e:
        raise error(path, "<file>", f"cannot read: {e.strerror or e}") from None
    except UnicodeDecodeError as e:
        raise error(path, "<file>", f"not UTF-8 text: {e.reason} at byte {e.start}") from None


def parse_yaml(text: str, path: Path | str, error: type[FileFieldError] = FileFieldError) -> Any:
    """`text` (the file `path`'s) as YAML, bounded as `read_yaml` says."""
    loader = _BoundedLoader(text)
    try:
        return loader.get_single_data()
    except _TooBig as e:
        raise error(Path(path), "<top>", str(e)) from None
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark else ""
        raise error(Path(path), "<top>", f"not valid YAML{where}: {e}") from None
    except (ValueError, RecursionError) as e:  # e.g. an integer of 10^5 digits
        raise error(Path(path), "<top>", f"not readable YAML: {type(e).__name__}: {e}") from None
    finally:
        loader.dispose()


STRICT = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
"""Every file schema's pydantic config (`__pydantic_config__` on its dataclasses)."""


@functools.cache
def _adapter(schema: type) -> TypeAdapter:
    return TypeAdapter(schema)


def _json_safe(value: Any) -> Any:
    """YAML values JSON has no word for (dates, ...) as text: the schema then names them."""
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_safe(v) for v in value]
    if value is None or isinstance(value, str | int | float | bool):
        return value
    return str(value)


def _non_finite(value: Any, loc: tuple = ()) -> tuple | None:
    """Where a NaN or an infinity is (YAML's .nan, .inf): no field takes one."""
    if isinstance(value, float) and not math.isfinite(value):
        return loc
    if isinstance(value, dict | list | tuple):
        for k, v in value.items() if isinstance(value, dict) else enumerate(value):
            if (found := _non_finite(v, (*loc, k))) is not None:
                return found
    return None


def _strip(tp: Any) -> Any:
    """The type under Annotated[...] and `| None`."""
    while True:
        if typing.get_origin(tp) is typing.Annotated:
            tp = typing.get_args(tp)[0]
        elif typing.get_origin(tp) in (typing.Union, types.UnionType):
            args = [a for a in typing.get_args(tp) if a is not type(None)]
            if len(args) != 1:
                return tp
            tp = args[0]
        else:
            return tp


def type_at(schema: type, loc: tuple) -> Any:
    """The schema's type at `loc` (None where it cannot tell)."""
    tp: Any = schema
    for part in loc:
        tp = _strip(tp)
        if dataclasses.is_dataclass(tp):
            tp = typing.get_type_hints(tp, include_extras=True).get(str(part))
        elif typing.get_origin(tp) is tuple and isinstance(part, int):
            args = typing.get_args(tp)
            tp = args[0] if args[-1] is Ellipsis else args[min(part, len(args) - 1)]
        elif typing.get_origin(tp) is dict:
            tp = typing.get_args(tp)[1]
        else:
            return None
    return _strip(tp)


def _fixed_length(tp: Any) -> int | None:
    args = typing.get_args(tp) if typing.get_origin(tp) is tuple else ()
    return len(args) if args and args[-1] is not Ellipsis else None


def _fields_at(schema: type, loc: tuple) -> list[str]:
    """The field names a key at `loc` may have (for "unknown key" messages)."""
    cls = type_at(schema, loc)
    if not dataclasses.is_dataclass(cls):
        return []
    hidden = getattr(cls, "NOT_IN_FILE", ())
    return [f.name for f in dataclasses.fields(cls) if f.init and f.name not in hidden]


def _message(schema: type, err: dict) -> str:
    kind, loc = err["type"], err["loc"]
    got = err.get("input")
    if kind in ("unexpected_keyword_argument", "extra_forbidden"):
        known = _fields_at(schema, loc[:-1])
        return "unknown key" + (f"; expected one of {', '.join(known)}" if known else "")
    if kind in ("missing", "missing_argument"):
        return "missing; a value is required"
    if kind == "fixed_length":
        return f"expected a list of {err['n']} values, got {got!r}"
    ctx = err.get("ctx") or {}
    if kind in BOUNDS:
        text = f"a value {BOUNDS[kind]} {next(iter(ctx.values())):g}"
    elif kind == "too_short":
        text = f"at least {ctx.get('min_length')} item(s)"
    elif kind == "too_long":
        text = f"at most {ctx.get('max_length')} item(s)"
    elif kind in TYPE_WORDS:
        text = TYPE_WORDS[kind]
    else:
        text = err["msg"].removeprefix("Input should be ").removeprefix("Value error, ")
    return f"expected {text}, got {got!r}"


def _at(data: Any, loc: tuple) -> Any:
    for part in loc:
        try:
            data = data[part]
        except (KeyError, IndexError, TypeError):
            return None
    return data


BOUNDS = {
    "greater_than": ">",
    "greater_than_equal": ">=",
    "less_than": "<",
    "less_than_equal": "<=",
}

TYPE_WORDS = {
    "int_type": "an integer",
    "float_type": "a number",
    "bool_type": "true or false",
    "string_type": "a string",
    "dict_type": "a mapping",
    "tuple_type": "a list",
    "list_type": "a list",
    "dataclass_type": "a mapping of fields",
}


def validate(
    schema: type[T],
    data: dict[str, Any],
    file: Path | str,
    error: type[FileFieldError] = FileFieldError,
) -> T:
    """`data` (a parsed YAML mapping) as a `schema` instance, or `error(file, field, what
    was expected)` for its first problem."""
    if not isinstance(data, dict):
        raise error(file, "<top>", f"expected a mapping, got {data!r}")
    if (where := _non_finite(data)) is not None:  # JSON has no word for them
        got = _at(data, where)
        raise error(file, ".".join(map(str, where)), f"expected a finite number, got {got}")
    try:
        return _adapter(schema).validate_json(json.dumps(_json_safe(data)), strict=True)
    except ValidationError as e:
        err = e.errors()[0]
        loc = tuple(err["loc"])
        # A list of the wrong length for a fixed one ([x, y] for x y z): name the list.
        n = None
        if loc and isinstance(loc[-1], int) and err["type"] in ("missing", "too_long"):
            n = _fixed_length(type_at(schema, loc[:-1]))
            loc = loc[:-1] if n is not None else loc
        if n is None and err["type"] in ("too_long", "tuple_type"):
            n = _fixed_length(type_at(schema, loc))
        if n is not None:
            err = {"type": "fixed_length", "n": n, "input": _at(data, loc), "loc": loc}
        field = ".".join(str(p) for p in loc) or "<top>"
        raise error(file, field, _message(schema, err)) from None


def validate_file(
    schema: type[T],
    path: Path | str,
    error: type[FileFieldError],
    prepare: Callable[[dict], dict] = lambda data: data,
) -> T:
    """A YAML file as a `schema` instance (`validate`). The schema's NOT_IN_FILE fields
    (`name`, `source`) come from the file's name and place, never from its text; `prepare`
    turns the parsed mapping into the schema's shape (shorthands a file may use)."""
    path = Path(path)
    data = read_yaml(path, error)
    if not isinstance(data, dict):
        raise error(path, "<top>", "expected a mapping of fields")
    for reserved in getattr(schema, "NOT_IN_FILE", ()):
        if reserved in data:
            raise error(path, reserved, "unknown key: the name is the file's")
    return validate(schema, {**prepare(data), "name": path.stem, "source": str(path)}, path, error)
