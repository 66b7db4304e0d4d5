"""PNG plots: success per agent per task, 6-DoF success vs hole tilt, servo times. Colours,
markers and line styles come from `style.py` (one colour per agent family); every rate is
drawn with its 95% Wilson interval; a panel holds at most `style.MAX_LINES` lines."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # no display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from cfvs_maniskill.report import style  # noqa: E402
from cfvs_maniskill.stats import wilson_interval  # noqa: E402

TILT_BINS = np.arange(0, 55, 10)
"""Hole tilt bins (deg) of the success-vs-tilt plot."""


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def line_label(rec: dict) -> str:
    """The record's label, with its sensor when it is not the ideal one."""
    sensor = rec.get("sensor", "ideal")
    return rec["label"] if sensor == "ideal" else f"{rec['label']} ({sensor})"


def _rate(ok: list[bool]) -> tuple[float, float, float]:
    k, n = int(sum(ok)), len(ok)
    if n == 0:
        return np.nan, np.nan, np.nan
    lo, hi = wilson_interval(k, n)
    return k / n, lo, hi


def heads(records: list[dict]) -> list[dict]:
    """The records of the families' own agents (CFVS, the baselines, the oracle): the
    paper's comparison; the rest are variants (ablations, other weights or settings)."""
    return [r for r in records if r["label"] == style.family(r["label"])]


def variants(records: list[dict]) -> list[dict]:
    return [r for r in records if r["label"] != style.family(r["label"])]


def success_per_agent(records: list[dict], out: Path, name: str = "success_per_agent") -> Path:
    """One panel per task: a horizontal bar per label (family colour, variant hatch) with
    its 95% interval."""
    tasks = sorted({r["task"] for r in records})
    labels = sorted({line_label(r) for r in records})
    look = style.looks(labels)
    order = style.order(labels)
    per_task = {
        t: [lb for lb in order if any(r["task"] == t and line_label(r) == lb for r in records)]
        for t in tasks
    }
    tall = max(len(v) for v in per_task.values())
    cols = min(3, len(tasks))
    rows = int(np.ceil(len(tasks) / cols))
    fig, axes = plt.subplots(
        rows, cols, figsize=(4.6 * cols, (0.9 + 0.26 * tall) * rows), squeeze=False
    )
    for ax, task in zip(axes.flat, tasks, strict=False):
        shown = per_task[task]
        for y, lb in enumerate(shown):
            ok = [r["success"] for r in records if r["task"] == task and line_label(r) == lb]
            p, lo, hi = _rate(ok)
            lk = look[lb]
            ax.barh(y, p, color=lk.colour, hatch=lk.hatch, edgecolor="white", height=0.8)
            err = [[max(p - lo, 0.0)], [max(hi - p, 0.0)]]  # float round-off at 0/n, n/n
            ax.errorbar(p, y, xerr=err, color="black", lw=0.8, capsize=2)
        ax.set_yticks(range(len(shown)), shown, fontsize=7)
        ax.set_ylim(tall - 0.5, -0.5)  # the same bar height in every panel, top down
        ax.set_xlim(0, 1.02)
        ax.set_title(task, fontsize=9)
        ax.set_xlabel("success (95% Wilson interval)", fontsize=8)
        ax.grid(axis="x", alpha=0.3)
    for ax in list(axes.flat)[len(tasks) :]:
        ax.set_visible(False)
    return _save(fig, out / f"{name}.png")


def success_vs_tilt(
    records: list[dict], out: Path, task: str = "PegInsert6DoF", name: str = "success_vs_tilt"
) -> Path:
    """Success per 10-deg bin of hole tilt on `task`, 95% bands (the paper's Fig. 6); the
    agents side by side, a family's variants beside their agent in panels of their own."""
    recs = [r for r in records if r["task"] == task]
    labels = sorted({line_label(r) for r in recs})
    groups = style.panels(labels) or [("agents", [])]
    cols = min(3, len(groups))
    rows = int(np.ceil(len(groups) / cols))
    fig, axes = plt.subplots(
        rows, cols, figsize=(4.6 * cols, 3.6 * rows), squeeze=False, sharey=True
    )
    centres = TILT_BINS[:-1] + 5
    for ax, (title, group) in zip(axes.flat, groups, strict=False):
        look = style.looks(group)  # line styles distinct within the panel
        for lb in group:
            tilt = np.array([r["tilt_deg"] for r in recs if line_label(r) == lb])
            ok = np.array([r["success"] for r in recs if line_label(r) == lb], dtype=bool)
            idx = np.digitize(tilt, TILT_BINS) - 1
            p, lo, hi = np.array([_rate(list(ok[idx == b])) for b in range(len(centres))]).T
            lk = look[lb]
            ax.plot(centres, p, color=lk.colour, marker=lk.marker, ls=lk.linestyle, label=lb)
            ax.fill_between(centres, lo, hi, color=lk.colour, alpha=0.12, lw=0)
        ax.set_title(f"{task}: {title}", fontsize=9)
        ax.set_xlabel("hole tilt from vertical (deg)")
        ax.set_ylim(0, 1.05)
        ax.grid(alpha=0.3)
        if group:  # a panel with no agent line has no legend (matplotlib warns otherwise)
            ax.legend(fontsize=7, loc="lower left")
    for ax in list(axes.flat)[len(groups) :]:
        ax.set_visible(False)
    for row in axes:
        row[0].set_ylabel("success (95% band)")
    return _save(fig, out / f"{name}.png")


def servo_times(records: list[dict], out: Path, name: str = "servo_time") -> Path:
    """Simulated servo time of the successes, a box per label in its family's colour."""
    labels = sorted({r["label"] for r in records})
    look = style.looks(labels)
    order = style.order(labels)
    data = [
        [r["servo_time_s"] for r in records if r["label"] == lb and r["success"]] for lb in order
    ]
    fig, ax = plt.subplots(figsize=(max(6, 0.55 * len(order)), 4))
    boxes = ax.boxplot([d if d else [np.nan] for d in data], tick_labels=order, patch_artist=True)
    for box, lb in zip(boxes["boxes"], order, strict=True):
        box.set(facecolor=look[lb].colour, alpha=0.55, hatch=look[lb].hatch)
    ax.set_ylabel("simulated servo time of successes (s)")
    ax.tick_params(axis="x", labelrotation=60, labelsize=7)
    ax.grid(axis="y", alpha=0.3)
    return _save(fig, out / f"{name}.png")
