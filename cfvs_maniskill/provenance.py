"""What produced a result record: the code, the weights, the sensor profile, the task and
the hole object, each by a version or a sha256, so that a table can say which code and
which files its numbers come from and a stale or mixed cell can be found (report --check)."""

from __future__ import annotations

import ast
import functools
import hashlib
import inspect
import subprocess
from collections.abc import Iterable
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path

from cfvs_maniskill.constants import PROJECT_ROOT

PACKAGE_DIR = Path(__file__).resolve().parent


@functools.cache
def code_version() -> str:
    """`git describe` of the checkout the package runs from (`+dirty` when its code differs
    from the commit), or the installed package's version outside a checkout."""
    try:
        top = _git("rev-parse", "--show-toplevel")
        if Path(top).resolve() == PROJECT_ROOT:
            described = _git("describe", "--tags", "--always", "--abbrev=12")
            # Only the code counts: results written into the tree during a run must not
            # make the run's own records "dirty".
            changed = _git("status", "--porcelain", "--", PACKAGE_DIR.name, "pyproject.toml")
            return described + ("+dirty" if changed else "")
    except (OSError, subprocess.CalledProcessError):
        pass
    try:
        return metadata.version("cfvs_maniskill")
    except metadata.PackageNotFoundError:
        return "unknown"


NOT_EPISODE_CODE = (
    *("report/", "data/", "policies/dataset.py"),
    *("sensing/floor.py", "sensing/texture_study.py"),  # analyses of the sensor models
    "bundled/",  # links to the user-file folders: hashed file by file in each record
    # Orchestration: which jobs run, where, and how their records are kept; an episode's
    # outcome is decided by the worker, the session and what they call.
    *("eval/__main__.py", "eval/local.py", "eval/ray_backend.py", "eval/crash.py"),
    *("eval/results.py", "eval/settings.py", "eval/summary.py", "run.py", "cli.py"),
)
"""Package paths that never decide an episode (tables, training, dataset collection, the
evaluation's orchestration), so their changes leave records current."""
POLICY_TOOLS = ("collect.py", "train.py", "diagnose.py")
"""A policy folder's dataset collection, training and diagnosis: not episode code either."""


def is_episode_code(path: str) -> bool:
    """Whether the module at `path` (in the package) can decide an episode."""
    if not path.endswith(".py") or path.startswith(NOT_EPISODE_CODE):
        return False
    return not (path.startswith("policies/") and path.rsplit("/", 1)[-1] in POLICY_TOOLS)


def _is_text(stmt: ast.stmt) -> bool:
    return (
        isinstance(stmt, ast.Expr)
        and isinstance(stmt.value, ast.Constant)
        and isinstance(stmt.value.value, str)
    )


def fingerprint(sources: Iterable[tuple[str, bytes]]) -> str:
    """A hash of the episode code among (path in the package, source) pairs: each module's
    syntax tree without its string statements (docstrings of modules, classes, functions
    and attributes), so a comment, a docstring or a layout change keeps it and a change to
    what runs moves it."""
    h = hashlib.sha256()
    for path, src in sorted(sources):
        if not is_episode_code(path):
            continue
        tree = ast.parse(src)
        for node in ast.walk(tree):
            for name in ("body", "orelse", "finalbody"):
                body = getattr(node, name, None)
                if isinstance(body, list) and any(isinstance(b, ast.stmt) for b in body):
                    kept = [b for b in body if not _is_text(b)]
                    setattr(node, name, kept or ([ast.Pass()] if name == "body" else []))
        h.update(f"{path}\0{ast.dump(tree)}\0".encode())
    return h.hexdigest()[:16]


@functools.cache
def code_fingerprint() -> str:
    """The fingerprint of the episode code this process runs (`fingerprint`)."""
    return fingerprint(
        (f.relative_to(PACKAGE_DIR).as_posix(), f.read_bytes()) for f in PACKAGE_DIR.rglob("*.py")
    )


def _git(*args: str) -> str:
    out = subprocess.run(
        ["git", "-C", str(PROJECT_ROOT), *args],
        capture_output=True,
        text=True,
        check=True,
        timeout=30,
    )
    return out.stdout.strip()


def file_key(path: Path | str) -> str:
    """A file's name in records: a bundled file by its name in the repository (the same in
    every checkout and installed wheel), another file of the checkout relative to its root,
    else its absolute path."""
    from cfvs_maniskill import resources

    if (bundled := resources.key(path)) is not None:
        return bundled
    p = Path(path).resolve()
    try:
        return p.relative_to(PROJECT_ROOT).as_posix()
    except ValueError:
        return str(p)


def file_sha256(path: Path | str) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(1 << 23):
            h.update(chunk)
    return h.hexdigest()


@functools.cache
def _sha256(path: Path, mtime_ns: int, size: int) -> str:
    return file_sha256(path)


def sha256(path: Path | str) -> str:
    """A file's sha256, computed once per process for an unchanged file."""
    p = Path(path).resolve()
    st = p.stat()
    return _sha256(p, st.st_mtime_ns, st.st_size)


def files_entry(*paths: Path | str) -> dict[str, str]:
    return {file_key(p): sha256(p) for p in paths}


_LOADED: list[dict[str, str]] = []


@contextmanager
def track_weights():
    """Collects {file: sha256} of every weights file loaded inside the block (nested blocks
    each see what was loaded inside them)."""
    loaded: dict[str, str] = {}
    _LOADED.append(loaded)
    try:
        yield loaded
    finally:
        _LOADED.remove(loaded)


def note_loaded(path: Path | str) -> None:
    """Called by the weights loader for every file it reads."""
    if _LOADED:
        entry = files_entry(path)
        for loaded in _LOADED:
            loaded.update(entry)


def agent_code(agent) -> dict[str, str]:
    """{file: sha256} of the module defining `agent`'s class when it lives outside this
    package (your own agent, `module:Class`): the fingerprint covers only the package."""
    try:
        source = inspect.getsourcefile(type(agent))
    except TypeError:  # a class without a source file (built in, made at run time)
        return {}
    if source is None or Path(source).resolve().is_relative_to(PACKAGE_DIR.resolve()):
        return {}
    return files_entry(source)


def of_episode(env, weights: dict[str, str], agent=None) -> dict:
    """The provenance of an episode on `env` by `agent`, which loaded `weights`."""
    u = env.unwrapped
    spec = u.object_specs[u.object_index]
    object_files = [spec.source, *([spec.mesh_file] if spec.mesh_file else [])]
    return {
        "code": code_version(),
        "code_fingerprint": code_fingerprint(),
        "agent_code": agent_code(agent),
        "weights": dict(sorted(weights.items())),
        "sensor": {"name": u.sensor_profile.name, **_one(u.sensor_profile.source)},
        "task": {"name": u.task.name, **_one(u.task.source)},
        "object": {"name": spec.name, "files": files_entry(*object_files)},
    }


def _one(path: Path | str) -> dict[str, str]:
    return {"file": file_key(path), "sha256": sha256(path)}
