"""Result records from every *.jsonl below a folder (eval runs and run-command files)."""

from __future__ import annotations

import json
from pathlib import Path


def init_label(rec: dict) -> str:
    if "init_error" in rec:
        return rec["init_error"]
    return "small" if rec["init_error_m"] < 0.225 else "large"


def load_records(root: Path) -> list[dict]:
    """Records with `label` (the agent, or the folder's name when it names a variant of
    that agent, e.g. results/cfvs_plain) and `init` (small / large)."""
    out = []
    for f in sorted(root.rglob("*.jsonl")):
        if "archive" in f.relative_to(root).parts[:-1]:
            continue  # earlier measurements kept for the record (other code, settings)
        folder = f.parent.name if f.parent != root else None
        for line in f.read_text().splitlines():
            if not line.strip():
                continue
            try:
                rec = json.loads(line)
            except ValueError:
                continue  # a torn last line of a running evaluation
            label = rec["agent"]
            if rec.get("search_radius_m") == 0:
                label += "_plain"  # the paper's protocol: no compliant search
            elif folder and folder.startswith(label + "_"):
                label = folder  # a variant's folder: results/cfvs_plain, results/3drhd_plain
            rec["label"], rec["init"] = label, init_label(rec)
            out.append(rec)
    return out
