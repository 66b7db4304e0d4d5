"""The results file: JSON lines, one finished episode each, appended and fsync'd one at a
time, so any kill loses at most the episode that was running."""

from __future__ import annotations

import fcntl
import gzip
import json
import os
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


class ResultsError(ValueError):
    """A results file that cannot be resumed; the message names the file and the line."""


def read_text(path: Path) -> str:
    """A result file's text; `.gz` files (finished runs, compressed for the repository)
    are read through gzip."""
    if path.suffix == ".gz":
        return gzip.decompress(path.read_bytes()).decode()
    return path.read_text()


def compressed(path: Path) -> Path:
    """Where a finished run's records are kept compressed: episodes.jsonl.gz."""
    return path.with_name(path.name + ".gz")


def read_done(path: Path) -> dict[str, dict]:
    """Finished records by job key, from `path` and its compressed copy (a run resumed after
    its records were compressed appends to `path`). A torn last line (a kill mid-write: no
    final newline) is cut off the file and its job runs again; a bad complete line is an
    error naming it."""
    done: dict[str, dict] = {}
    if compressed(path).exists():
        try:
            done = {r["key"]: r for r in map(json.loads, read_text(compressed(path)).splitlines())}
        except (
            OSError,
            EOFError,
            zlib.error,
            ValueError,
            KeyError,
            TypeError,
            RecursionError,
        ) as e:
            raise ResultsError(
                f"{compressed(path)}: not a compressed results file ({type(e).__name__}: {e}); "
                "restore it or move it away to resume"
            ) from e
    if not path.exists():
        return done
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise ResultsError(f"{path}: cannot read the results ({e.strerror or e})") from e
    end = raw.rfind(b"\n") + 1  # everything after the last newline is torn
    if end < len(raw):
        try:
            with open(path, "r+b") as f:
                f.truncate(end)
        except OSError as e:
            raise ResultsError(
                f"{path}: its torn last line cannot be cut off ({e.strerror or e}); "
                "make the file writable to resume"
            ) from e
    for i, line in enumerate(raw[:end].split(b"\n")):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
            done[rec["key"]] = rec
        except (ValueError, KeyError, TypeError, RecursionError) as e:
            raise ResultsError(
                f"{path}: line {i + 1} is not a result record ({type(e).__name__}: {e}); "
                "fix or remove that line to resume"
            ) from e
    return done


def fold_into_compressed(path: Path) -> None:
    """A finished run resumed on a compressed folder: its new records in `path` join the
    compressed file (written aside, then renamed over it) and `path` goes, so that
    compressing the folder again cannot put the new records in place of the old."""
    gz = compressed(path)
    if not (gz.exists() and path.exists()):
        return
    old = read_text(gz)
    _replace(gz, old + ("\n" if old and not old.endswith("\n") else "") + path.read_text())
    path.unlink()  # a kill before this leaves records in both: read once by key


def _replace(f: Path, text: str) -> None:
    """Write `text` as results file `f` (compressed for `.gz`) aside, then rename it over
    `f`: a kill leaves either file whole."""
    data = text.encode()
    tmp = f.with_name(f.name + ".tmp")
    tmp.write_bytes(gzip.compress(data, compresslevel=9, mtime=0) if f.suffix == ".gz" else data)
    os.replace(tmp, f)


FROZEN_RESULTS = (
    "results/final",
    "results/generalisation",
    "results/generalisation_grooved",
    "results/generalisation_plates",
    "results/generalisation_fixtures",
    "results/generalisation_housings",
    "results/generalisation_manifolds",
    "results/generalisation_castings",
    "results/generalisation_wheels",
    "results/generalisation_links",
)
"""The results folders of the frozen sets (assets/final, assets/generalisation*), relative
to the checkout: each record there is what its release's one run wrote, never re-run."""


def frozen(folder: Path) -> str | None:
    """The frozen results folder `folder` lies in (FROZEN_RESULTS), or None."""
    from cfvs_maniskill.constants import PROJECT_ROOT

    at = folder.resolve()
    return next((f for f in FROZEN_RESULTS if at.is_relative_to(PROJECT_ROOT / f)), None)


def drop(path: Path, keys: set[str]) -> None:
    """Remove the records of `keys` from `path` and its compressed copy (`_replace`)."""
    for f in (compressed(path), path):
        if not f.exists():
            continue
        lines = read_text(f).splitlines()
        _replace(
            f,
            "".join(f"{ln}\n" for ln in lines if ln.strip() and json.loads(ln)["key"] not in keys),
        )


def append(path: Path, record: dict) -> None:
    """Append one record, or leave the file exactly as it was: a failed write (disk full,
    file-size limit) is cut back off, so the file never holds half a line."""
    data = (json.dumps(record) + "\n").encode()
    try:
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    except OSError as e:
        raise ResultsError(f"{path}: cannot write results ({e.strerror or e})") from e
    try:
        size = os.fstat(fd).st_size
        try:
            view = memoryview(data)
            while view:  # os.write may write part of it (e.g. up to a size limit)
                view = view[os.write(fd, view) :]
            os.fsync(fd)
        except OSError as e:
            os.ftruncate(fd, size)
            raise ResultsError(
                f"{path}: cannot append a result ({e.strerror or e}); the results already "
                "there are intact: free some space and run the same command again to resume"
            ) from e
    finally:
        os.close(fd)


@contextmanager
def exclusive(path: Path) -> Iterator[None]:
    """One writer at a time for a results file: a lock on `<file>.lock` beside it, which the
    kernel drops when its process ends, however it ends (a kill leaves nothing behind). A
    second writer gets a ResultsError naming the process that holds it."""
    lock = path.with_name(path.name + ".lock")
    try:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as e:
        raise ResultsError(f"{lock}: cannot create the lock ({e.strerror or e})") from e
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 64, 0).decode(errors="replace").strip() or "another process"
            raise ResultsError(
                f"{path}: {holder} is writing these results; wait for it to end, or use "
                "another --out"
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"process {os.getpid()}".encode(), 0)
        yield
    finally:
        os.close(fd)
