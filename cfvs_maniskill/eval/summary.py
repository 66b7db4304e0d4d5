"""A plain summary of an episodes.jsonl: success per task x agent x initial error."""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

from cfvs_maniskill.eval.results import read_done
from cfvs_maniskill.stats import wilson_interval


def write_summary(path: Path, out: Path, config: dict) -> str:
    cells: dict[tuple, list[dict]] = defaultdict(list)
    crashed = []
    for rec in read_done(path).values():
        if rec.get("crashed"):
            crashed.append(rec)  # no outcome: in no success rate, listed below
            continue
        sensor = rec.get("sensor", "ideal")  # records from before sensor profiles: ideal
        cells[(rec["task"], rec["agent"], rec["init_error"], sensor)].append(rec)
    rows = [
        "| task | agent | initial error | sensor | episodes | success | 95% CI | mean servo time |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for (task, agent, err, sensor), recs in sorted(cells.items()):
        k, n = sum(r["success"] for r in recs), len(recs)
        lo, hi = wilson_interval(k, n)
        servo = sum(r["servo_time_s"] for r in recs) / n
        rows.append(
            f"| {task} | {agent} | {err} | {sensor} | {n} | {k}/{n} = {k / n:.3f} | {lo:.3f}-{hi:.3f} "
            f"| {servo:.2f} s |"
        )
    if crashed:
        rows += [
            "",
            f"{len(crashed)} crashed jobs (no outcome; `--retry-crashed` runs them again):",
        ]
        rows += [f"- {r['key']}: {r['reason']}" for r in crashed]
    text = "\n".join(rows)
    cfg = json.dumps({k: str(v) for k, v in config.items()})
    out.write_text(f"# Evaluation summary\n\nArguments: `{cfg}`\n\n{text}\n")
    return text
