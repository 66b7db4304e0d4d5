"""Which code and files each table cell comes from, and whether it is still what today's
code and files would give: a cell is *mixed* when its records differ in code version,
weights, sensor profile or task file, and *stale* when they were made with weights, a
sensor profile, a task or hole file that is not today's (or with no provenance at all)."""

from __future__ import annotations

import functools
import json
from collections import Counter
from pathlib import Path

from cfvs_maniskill.constants import PROJECT_ROOT
from cfvs_maniskill.provenance import sha256


def signature(rec: dict) -> tuple:
    """What must agree between the records of one cell (the object's files may differ: a
    cell averages over objects)."""
    p = rec.get("provenance") or {}
    return (
        p.get("code"),
        json.dumps(p.get("weights"), sort_keys=True),
        (p.get("sensor") or {}).get("sha256"),
        (p.get("task") or {}).get("sha256"),
    )


def _today(file: str) -> str | None:
    """sha256 of a recorded file as it is today (None: gone)."""
    path = Path(file) if Path(file).is_absolute() else PROJECT_ROOT / file
    return sha256(path) if path.is_file() else None


@functools.cache
def agent_weights_today(agent: str, task: str) -> dict[str, str] | None:
    """{file: sha256} the agent loads today for the task, None: it cannot be built."""
    from cfvs_maniskill import TASKS
    from cfvs_maniskill.agents.interface import TaskSpec
    from cfvs_maniskill.agents.registry import PRIVILEGED, resolve_agent
    from cfvs_maniskill.provenance import track_weights

    if agent in PRIVILEGED:
        return {}  # the oracle loads nothing
    try:
        factory = resolve_agent(agent)
        with track_weights() as loaded:
            factory(TaskSpec.of(TASKS[task]))
    except Exception:  # removed from the registry, no weights for the task, ...
        return None
    return loaded


def stale_reasons(rec: dict) -> list[str]:
    """Why a record is not what today's code and files would give (empty: current)."""
    p = rec.get("provenance")
    if not p:
        return ["no provenance"]
    out = []
    for kind in ("sensor", "task"):
        entry = p.get(kind) or {}
        if entry.get("file") and _today(entry["file"]) != entry.get("sha256"):
            out.append(f"{kind} file {entry['file']} changed since")
    for file, sha in ((p.get("object") or {}).get("files") or {}).items():
        if _today(file) != sha:
            out.append(f"hole file {file} changed since")
    if p.get("weights") is None:
        out.append("weights unknown")
    else:
        today = agent_weights_today(rec["agent"], rec["task"])
        if today is None:
            out.append(f"agent {rec['agent']} cannot be built today")
        elif today != p["weights"]:
            changed = sorted(set(today.items()) ^ set(p["weights"].items()))
            out.append("other weights today: " + ", ".join(sorted({f for f, _ in changed})))
    return out


def cell_status(recs: list[dict]) -> tuple[str, list[str]]:
    """("ok" | "mixed" | "stale" | "crashed", reasons) of one table cell's records."""
    reasons: Counter = Counter()
    if any(r.get("crashed") for r in recs):
        reasons["crashed jobs (eval --retry-crashed)"] += 1
    sigs = {signature(r) for r in recs}
    if len(sigs) > 1:
        codes = sorted({str(s[0]) for s in sigs})
        reasons[f"mixed: {len(sigs)} provenances (code {', '.join(codes)})"] += 1
    for r in recs:
        for why in stale_reasons(r):
            reasons[why] += 1
    if not reasons:
        return "ok", []
    kind = (
        "crashed"
        if any(k.startswith("crashed") for k in reasons)
        else "mixed"
        if any(k.startswith("mixed") for k in reasons)
        else "stale"
    )
    return kind, [f"{k} ({n} records)" if n > 1 else k for k, n in reasons.items()]


def code_versions(recs: list[dict]) -> str:
    """'abc123 (180), def456 (20)': the code versions of some records, most first."""
    c = Counter(str((r.get("provenance") or {}).get("code")) for r in recs)
    return ", ".join(f"{k} ({n})" for k, n in c.most_common())
