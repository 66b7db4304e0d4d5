"""Result records from every *.jsonl (or *.jsonl.gz: finished runs, compressed for the
repository) below a folder (eval runs and run-command files)."""

from __future__ import annotations

import functools
import json
import sys
import zlib
from pathlib import Path

from cfvs_maniskill.eval.results import read_text
from cfvs_maniskill.objects.library import load_library


class ReportError(ValueError):
    """A result file the report cannot read: the message names the file, the line and what
    was expected there."""


def _parse(f: Path) -> list[tuple[int, dict]]:
    """(line number, record) of a result file. A line that is not a record is an error
    naming it, except the last line of a plain file an evaluation may still be writing
    (torn mid-write), which is left out with a note."""
    try:
        lines = read_text(f).splitlines()
    except (OSError, EOFError, zlib.error, UnicodeDecodeError) as e:
        raise ReportError(f"{f}: cannot be read as results ({type(e).__name__}: {e})") from None
    out = []
    for i, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
            if not isinstance(rec, dict):
                raise ValueError("not a JSON object")
        except (ValueError, RecursionError) as e:  # RecursionError: nested past JSON's limit
            if i == len(lines) and f.suffix == ".jsonl":
                print(f"report: {f}:{i}: a torn last line left out (a running evaluation?)")
                continue
            raise ReportError(f"{f}:{i}: not a result record ({e}); fix or remove it") from None
        if not rec.get("crashed") and not isinstance(rec.get("success"), bool):
            raise ReportError(
                f"{f}:{i}: field `success` is {rec.get('success')!r}: expected true or false"
            )
        out.append((i, rec))
    return out


def init_label(rec: dict) -> str:
    if "init_error" in rec:
        return rec["init_error"]
    return "small" if rec["init_error_m"] < 0.225 else "large"


@functools.cache
def _dof(task: str, file: str | None) -> int:
    from cfvs_maniskill.envs.lookup import task_named

    try:
        return task_named(task, file).dof
    except ValueError:  # a task (file) gone since: the name says it for ours
        digit = task.removeprefix("PegInsert")[:1]
        return int(digit) if digit.isdigit() else 0


def task_dof(rec: dict) -> int:
    """The degrees of freedom of the record's task (its task file's `dof`)."""
    from cfvs_maniskill.envs.lookup import recorded_file

    return _dof(rec["task"], recorded_file(rec, "task"))


def load_records(
    root: Path, crashed: list[dict] | None = None, assets: tuple[Path, ...] = ()
) -> list[dict]:
    """Records with `label` (the agent, or the folder's name when it names a variant of
    that agent, e.g. results/cfvs_plain) and `init` (small / large).

    Crashed jobs (no outcome) go to `crashed` instead. Records on objects outside the
    default library and `assets` (e.g. the CAD parts in results/cad_parts_v3 without
    `--assets assets/cad_parts`) are left out: a table averages over the objects it names.
    A line that is not a record, or a record whose `success` is not true or false, raises
    ReportError naming the file and line (a torn last line of a plain file is left out).
    """
    known = set(load_library(assets).specs)
    out, other = [], 0
    crashed = [] if crashed is None else crashed
    files = [*root.rglob("*.jsonl"), *root.rglob("*.jsonl.gz")]
    # A folder's compressed records first, then what a resumed run appended beside them.
    files.sort(key=lambda f: (str(f.parent), f.suffix != ".gz", f.name))
    by_folder: dict[Path, dict] = {}
    for f in files:
        if "archive" in f.relative_to(root).parts[:-1]:
            continue  # earlier measurements kept for the record (other code, settings)
        by_key = by_folder.setdefault(f.parent, {})
        for i, rec in _parse(f):
            # an eval's job re-run (--retry-crashed) replaces its record
            by_key[rec.get("key", (f.name, i))] = rec
    for parent, by_key in by_folder.items():
        folder = parent.name if parent != root else None
        for rec in by_key.values():
            if rec.get("object") not in known:
                other += 1
                continue
            label = rec["agent"]
            if rec.get("search_radius_m") == 0:
                label += "_plain"  # the paper's protocol: no compliant search
            elif folder and folder.startswith(label + "_"):
                label = folder  # a variant's folder: results/cfvs_plain, results/3drhd_plain
            rec["label"], rec["init"] = label, init_label(rec)
            rec["dof"] = task_dof(rec)
            rec.setdefault("sensor", "ideal")  # records from before sensor profiles
            rec.setdefault("mount", "flange_side")  # ... and before mounts were named
            # A crashed job has no outcome: in no success rate, listed by the report.
            (crashed if rec.get("crashed") else out).append(rec)
    if crashed:
        print(
            f"report: {len(crashed)} crashed jobs left out of every success rate: "
            + ", ".join(r["key"] for r in crashed[:5])
            + (" ..." if len(crashed) > 5 else ""),
            file=sys.stderr,
        )
    if other:
        print(
            f"report: {other} records on objects outside the default library left out "
            "(--assets DIR adds a folder of hole objects)",
            file=sys.stderr,
        )
    return out
