"""Markdown tables shaped like the paper's Tables II-IV, ours beside the paper's."""

from __future__ import annotations

from collections import Counter, defaultdict

from cfvs_maniskill.report import paper
from cfvs_maniskill.stats import wilson_interval

INITS = ("small", "large")


def _cell(recs: list[dict]) -> str:
    if not recs:
        return "-"
    k, n = sum(r["success"] for r in recs), len(recs)
    lo, hi = wilson_interval(k, n)
    return f"{k / n:.2f} [{lo:.2f}, {hi:.2f}] (n={n})"


def _task_dof(records: list[dict], task: str) -> int:
    return next(r["dof"] for r in records if r["task"] == task)


def _paper_task(task: str, dof: int) -> bool:
    """One of the paper's three tasks (not a tight fit, not a task of the user's)."""
    return task == f"PegInsert{dof}DoF"


def table_ii(records: list[dict]) -> str:
    """Per task: success at 15 / 30 cm per agent, on average and per paper object."""
    by = defaultdict(list)
    for r in records:
        by[(r["task"], r["label"], r["object"], r["init"])].append(r)
    tasks = sorted({r["task"] for r in records})
    labels = sorted({r["label"] for r in records})
    out = []
    for task in tasks:
        dof = _task_dof(records, task)
        present = {r["object"] for r in records if r["task"] == task}
        # The paper's four columns, or the objects of the user's own shapes.
        objects = paper.OBJECTS if present <= set(paper.OBJECTS) else tuple(sorted(present))
        out += [
            f"### {task}: success, ours [95% Wilson] / paper (15 cm | 30 cm)",
            "",
            "| agent | average 15 cm | paper | average 30 cm | paper | "
            + " | ".join(objects)
            + " |",
            "|---|---|---|---|---|" + "---|" * len(objects),
        ]
        for label in labels:
            recs = [r for r in records if r["task"] == task and r["label"] == label]
            if not recs:
                continue
            ref = _paper_row(task, label, dof) if objects == paper.OBJECTS else None
            avg = [_cell([r for r in recs if r["init"] == i]) for i in INITS]
            pav = [f"{ref[0][j]:.2f}" if ref else "-" for j in range(2)]
            objs = []
            for j, o in enumerate(objects):
                mine = [by[(task, label, o, i)] for i in INITS]
                frac = " / ".join(
                    f"{sum(r['success'] for r in m) / len(m):.2f}" if m else "-" for m in mine
                )
                objs.append(frac + (f" ({ref[j + 1][0]:.2f} / {ref[j + 1][1]:.2f})" if ref else ""))
            out.append(
                f"| {label} | {avg[0]} | {pav[0]} | {avg[1]} | {pav[1]} | "
                + " | ".join(objs)
                + " |"
            )
        out.append("")
    out.append("Per object: ours 15 / 30 cm (paper's 15 / 30 cm).")
    return "\n".join(out)


def _paper_row(task: str, label: str, dof: int):
    """The paper's Table II row for an agent on one of its three tasks (None for tasks the
    paper has not, e.g. tight fits; `_plain` labels are the paper's protocol itself)."""
    if not _paper_task(task, dof):
        return None
    return paper.TABLE_II.get(dof, {}).get(label.removesuffix("_plain"))


def table_sensors(records: list[dict]) -> str:
    """Per task: each agent's success at 15 / 30 cm under every sensor profile in the
    results, side by side, with the paper's (its protocol is the `ideal` profile)."""
    sensors = sorted({r["sensor"] for r in records}, key=lambda s: (s != "ideal", s))
    head = " | ".join(f"{s} {d}" for s in sensors for d in ("15 cm", "30 cm"))
    out = []
    for task in sorted({r["task"] for r in records}):
        out += [
            f"### {task}: success per sensor profile, ours [95% Wilson] (paper: ideal sensor)",
            "",
            f"| agent | {head} | paper 15 cm | paper 30 cm |",
            "|---|" + "---|" * (2 * len(sensors) + 2),
        ]
        for label in sorted({r["label"] for r in records if r["task"] == task}):
            recs = [r for r in records if r["task"] == task and r["label"] == label]
            cells = [
                _cell([r for r in recs if r["sensor"] == s and r["init"] == i])
                for s in sensors
                for i in INITS
            ]
            ref = _paper_row(task, label, _task_dof(records, task))
            pav = [f"{ref[0][j]:.2f}" if ref else "-" for j in range(2)]
            out.append(f"| {label} | " + " | ".join(cells) + f" | {pav[0]} | {pav[1]} |")
        out.append("")
    return "\n".join(out)


def table_compact(records: list[dict]) -> str:
    """One row per agent and task: success k/n at 15 / 30 cm per sensor profile, the
    paper's beside (the README's results table)."""
    sensors = sorted({r["sensor"] for r in records}, key=lambda s: (s != "ideal", s))
    head = " | ".join(f"{s} 15 / 30 cm" for s in sensors)
    out = [
        f"| agent | task | {head} | paper 15 / 30 cm |",
        "|---|---|" + "---|" * len(sensors) + "---|",
    ]
    for label in sorted({r["label"] for r in records}, key=lambda x: (x != "oracle", x)):
        for task in sorted({r["task"] for r in records if r["label"] == label}):
            recs = [r for r in records if r["task"] == task and r["label"] == label]
            cells = []
            for s in sensors:
                parts = []
                for i in INITS:
                    m = [r for r in recs if r["sensor"] == s and r["init"] == i]
                    k = sum(r["success"] for r in m)
                    parts.append(f"{k}/{len(m)} = {k / len(m):.2f}" if m else "-")
                cells.append(" / ".join(parts))
            dof = _task_dof(records, task)
            ref = _paper_row(task, label, dof)
            pav = f"{ref[0][0]:.2f} / {ref[0][1]:.2f}" if ref else "-"
            name = f"{dof}-DoF" if _paper_task(task, dof) else task  # e.g. tight fits
            out.append(f"| {label} | {name} | " + " | ".join(cells) + f" | {pav} |")
    return "\n".join(out)


def table_iii(records: list[dict]) -> str:
    """3-DoF servo time of successful episodes, per agent."""
    out = [
        "| agent | 15 cm | paper | 30 cm | paper |",
        "|---|---|---|---|---|",
    ]
    labels = sorted({r["label"] for r in records if r["dof"] == 3})
    for label in labels:
        cells = []
        for i in INITS:
            t = [
                r["servo_time_s"]
                for r in records
                if r["dof"] == 3 and r["label"] == label and r["init"] == i and r["success"]
            ]
            cells.append(f"{sum(t) / len(t):.1f} s (n={len(t)})" if t else "-")
        ref = paper.TABLE_III.get(label, ("-", "-"))
        out.append(f"| {label} | {cells[0]} | {ref[0]} | {cells[1]} | {ref[1]} |")
    return "\n".join(out)


def table_iv(records: list[dict]) -> str:
    """6-DoF ablation: success over both distances, per CFVS variant, under the paper's
    protocol (no compliant search, which would rescue what a component leaves off)."""
    out = ["| variant | success (6-DoF, 15 + 30 cm) | paper |", "|---|---|---|"]
    for label, ref in paper.TABLE_IV.items():
        recs = [r for r in records if r["dof"] == 6 and r["label"] == f"{label}_plain"]
        out.append(f"| {label} | {_cell(recs)} | {ref:.2f} |")
    return "\n".join(out)


HEADLINE_AGENTS = ("cfvs", "cfvs_plain", "3drhd", "icp_kpts", "icp", "kovis", "oracle")
"""The README's rows: CFVS (with and without the compliant search), the baselines, the
ceiling."""
HEADLINE_TASKS = ("PegInsert3DoF", "PegInsert4DoF", "PegInsert6DoF")
HEADLINES = {"headline": ("ideal", "realistic"), "headline-cameras": ("d435", "textured")}
"""The README's marked tables and their sensor profiles: the paper's and the D405's, then
the other cameras (an active-stereo D435, a D405 on textured parts)."""


def headline_cells(records: list[dict]) -> dict[tuple, list[dict]]:
    """(agent, task, sensor, initial error) -> the records of that headline cell."""
    sensors = {s for group in HEADLINES.values() for s in group}
    cells: dict[tuple, list[dict]] = defaultdict(list)
    for r in records:
        head = r["label"] in HEADLINE_AGENTS and r["task"] in HEADLINE_TASKS
        if head and r["sensor"] in sensors:
            cells[(r["label"], r["task"], r["sensor"], r["init"])].append(r)
    return cells


def table_provenance(records: list[dict], crashed: list[dict]) -> str:
    """Per agent, task and sensor profile: the records' code versions and whether they are
    of one provenance and current (report/trace.py)."""
    from cfvs_maniskill.report import trace

    cells: dict[tuple, list[dict]] = defaultdict(list)
    for r in records + crashed:
        cells[(r["label"], r["task"], r["sensor"])].append(r)
    out = [
        "`mixed`: the records differ in code, weights, sensor or task file; `stale`: made "
        "with files that are not today's; `crashed`: jobs without an outcome.",
        "",
        "| agent | task | sensor | episodes | code (records) | status |",
        "|---|---|---|---|---|---|",
    ]
    for (label, task, sensor), recs in sorted(cells.items()):
        status, reasons = trace.cell_status(recs)
        note = status if status == "ok" else f"**{status}**: {'; '.join(reasons)}"
        out.append(
            f"| {label} | {task} | {sensor} | {len(recs)} | {trace.code_versions(recs)} | {note} |"
        )
    return "\n".join(out)


def table_agent_errors(records: list[dict], limit: int = 50) -> str:
    """The episodes that ended on an agent's own error (it raised, or returned something
    that is not an action): failures in every table above, listed here so none hides."""
    failed = [r for r in records if r.get("agent_error")]
    if not failed:
        return "None: no agent raised or returned a malformed action."
    out = [
        f"{len(failed)} episodes, counted as failures"
        + (f"; the first {limit}:" if len(failed) > limit else ":"),
        "",
        "| agent | task | sensor | object | seed | decision | error |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in failed[:limit]:
        e = r["agent_error"]
        text = f"{e.get('type')}: {e.get('message', '')}".replace("|", "/").replace("\n", " ")[:160]
        out.append(
            f"| {r['label']} | {r['task']} | {r['sensor']} | {r.get('object')} | {r.get('seed')} "
            f"| {e.get('decision')} | {text} |"
        )
    return "\n".join(out)


def _usual_mounts(records: list[dict]) -> dict[str, str]:
    """Per sensor profile, the mount most of its records were made on (the profile's own;
    load.py names the mount of older records)."""
    counts: dict[str, Counter] = defaultdict(Counter)
    for r in records:
        counts[r["sensor"]][r["mount"]] += 1
    return {s: c.most_common(1)[0][0] for s, c in counts.items()}


def table_headline(records: list[dict], sensors: tuple[str, ...] = HEADLINES["headline"]) -> str:
    """Success at 15 / 30 cm per agent, task and sensor profile, the main agents only (the
    README's tables; everything else is in the report)."""
    head = " | ".join(f"{t[len('PegInsert') :]} {s}" for t in HEADLINE_TASKS for s in sensors)
    out = [f"| agent | {head} |", "|---|" + "---|" * len(HEADLINE_TASKS) * len(sensors)]
    shown = [r for r in records if r["sensor"] in sensors and r["task"] in HEADLINE_TASKS]
    usual = _usual_mounts(shown)
    for label in HEADLINE_AGENTS:
        recs = [r for r in shown if r["label"] == label]
        if not recs:
            continue
        # an agent trained for another mount than its profile's runs on it: say so
        if any(r["mount"] != usual[r["sensor"]] for r in recs):
            label = f"{label} ({', '.join(sorted({r['mount'] for r in recs}))} mount)"
        cells = []
        for t in HEADLINE_TASKS:
            for s in sensors:
                rates = []
                for i in INITS:
                    m = [r for r in recs if r["task"] == t and r["sensor"] == s and r["init"] == i]
                    rates.append(f"{sum(r['success'] for r in m) / len(m):.2f}" if m else "-")
                cells.append(" / ".join(rates))
        out.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(out)


def fill_headlines(text: str, records: list[dict], where: str) -> str:
    """`text` with every headline table whose markers it has filled from `records`; the
    first (`headline`) must be there (ValueError naming `where`)."""
    for name, sensors in HEADLINES.items():
        if name == "headline" or f"<!-- report:{name} begin -->" in text:
            text = replace_marked(text, name, table_headline(records, sensors), where)
    return text


def replace_marked(text: str, name: str, block: str, where: str) -> str:
    """`text` with the part between `<!-- report:NAME begin -->` and `<!-- report:NAME end
    -->` replaced by `block`; ValueError naming `where` when the markers are missing."""
    begin, end = f"<!-- report:{name} begin -->", f"<!-- report:{name} end -->"
    a, b = text.find(begin), text.find(end)
    if a < 0 or b < a:
        raise ValueError(f"{where}: no '{begin}' ... '{end}' markers to fill")
    return text[: a + len(begin)] + "\n" + block + "\n" + text[b:]
