"""Give every committed result record made before records carried provenance a provenance
reconstructed from git (run once; the records it wrote say so in `reconstructed`).

For each record: the commit that added its line (`git blame`), and the sha256 of the files
its agent, sensor profile, task and hole object use today's paths for, as they were in that
commit. The code that made a record is that commit or an earlier one; a weights file that
has changed since shows as stale in `report --check`.

    .venv/bin/python scripts/backfill_provenance.py results
"""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from functools import cache
from pathlib import Path

from tqdm import tqdm

from cfvs_maniskill.constants import PROJECT_ROOT
from cfvs_maniskill.objects.library import load_library
from cfvs_maniskill.provenance import file_key
from cfvs_maniskill.report.trace import agent_weights_today

NOTE = (
    "from git: the commit that added this record (the code that made it is this commit or "
    "an earlier one); files hashed as they were in that commit at today's paths"
)


def git(*args: str) -> str:
    return subprocess.run(
        ["git", "-C", str(PROJECT_ROOT), *args], capture_output=True, text=True, check=True
    ).stdout


@cache
def tree(commit: str) -> dict[str, str]:
    """path -> blob id of the files an episode depends on, in `commit`."""
    out = {}
    for line in git(
        "ls-tree", "-r", commit, "--", "agents", "sensors", "tasks", "assets"
    ).splitlines():
        meta, path = line.split("\t", 1)
        out[path] = meta.split()[2]
    return out


@cache
def blob_sha256(blob: str) -> str:
    data = subprocess.run(
        ["git", "-C", str(PROJECT_ROOT), "cat-file", "blob", blob], capture_output=True, check=True
    ).stdout
    return hashlib.sha256(data).hexdigest()


def at(commit: str, path: str) -> str:
    blob = tree(commit).get(path)
    return blob_sha256(blob) if blob else f"absent in {commit[:12]}"


@cache
def weights_paths(agent: str, task: str) -> tuple[str, ...] | None:
    w = agent_weights_today(agent, task)
    return None if w is None else tuple(sorted(w))


def provenance(rec: dict, commit: str, objects: dict[str, list[str]]) -> dict:
    paths = weights_paths(rec["agent"], rec["task"]) if "task" in rec else None
    sensor = rec.get("sensor", "ideal")
    out = {
        "code": commit[:12],
        "reconstructed": NOTE,
        "weights": None if paths is None else {p: at(commit, p) for p in paths},
        "sensor": {"name": sensor, "file": f"sensors/{sensor}.yaml"},
        "task": {"name": rec.get("task"), "file": f"tasks/{rec.get('task')}.yaml"},
    }
    for kind in ("sensor", "task"):
        out[kind]["sha256"] = at(commit, out[kind]["file"])
    files = objects.get(rec.get("object", ""))
    out["object"] = {
        "name": rec.get("object"),
        "files": None if files is None else {f: at(commit, f) for f in files},
    }
    return out


def main(root: Path) -> None:
    dirs = [str(d) for d in sorted((PROJECT_ROOT / "assets").iterdir()) if d.is_dir()]
    specs = load_library(dirs, include_default=False)
    objects = {
        name: [file_key(s.source), *([file_key(s.mesh_file)] if s.mesh_file else [])]
        for name, s in specs.specs.items()
    }
    files = sorted(root.rglob("*.jsonl"))
    for f in tqdm(files, desc="files"):
        rel = f.resolve().relative_to(PROJECT_ROOT).as_posix()
        commits = [line[:40] for line in git("blame", "-l", "-s", "--", rel).splitlines()]
        lines = f.read_text().splitlines()
        if len(commits) != len(lines):
            sys.exit(f"{f}: {len(lines)} lines, git blame gives {len(commits)}: commit it first")
        out, added = [], 0
        for line, commit in zip(lines, commits, strict=True):
            if not line.strip():
                out.append(line)
                continue
            rec = json.loads(line)
            if "provenance" not in rec:
                rec["provenance"] = provenance(rec, commit, objects)
                added += 1
            out.append(json.dumps(rec))
        if added:
            f.write_text("\n".join(out) + "\n")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
