"""A plain summary of an episodes.jsonl: success per task x agent x initial error."""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

from cfvs_maniskill.eval.results import read_done
from cfvs_maniskill.stats import wilson_interval


def write_summary(path: Path, out: Path, config: dict, settings=None) -> str:
    """summary.md of the records in `path`: a table per cell, the crashed jobs, the settings
    every record was made with (`settings`, checked by eval before it ran: settings.py) and
    the arguments of the run that wrote it, said as such (earlier runs may have added
    other tasks or agents to the folder)."""
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
    agent_errors = sum(1 for recs in cells.values() for r in recs if r.get("agent_error"))
    if agent_errors:
        rows += ["", f"{agent_errors} episodes failed on an agent's own error (counted above):"]
        rows += [
            f"- {r['key']}: {r['reason']}"
            for recs in cells.values()
            for r in recs
            if r.get("agent_error")
        ][:20]
    text = "\n".join(rows)
    head = ""
    if settings is not None:
        head = (
            f"Every record here: base seed {settings.seed}, search radius "
            f"{settings.search_radius} m; sensor files "
            + ", ".join(f"{k} {v[:12]}" for k, v in sorted(settings.sensors.items()))
            + "; task files "
            + ", ".join(f"{k} {v[:12]}" for k, v in sorted(settings.tasks.items()))
            + " (sha256) for the sensors and tasks of the last run.\n\n"
        )
    cfg = json.dumps({k: str(v) for k, v in config.items()})
    out.write_text(f"# Evaluation summary\n\n{head}The last run's arguments: `{cfg}`\n\n{text}\n")
    return text
