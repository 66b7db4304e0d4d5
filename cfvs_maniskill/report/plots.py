"""PNG plots: success per agent per task, 6-DoF success vs hole tilt, servo times."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # no display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from cfvs_maniskill.stats import wilson_interval  # noqa: E402


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def success_per_agent(records: list[dict], out: Path) -> Path:
    tasks = sorted({r["task"] for r in records})
    labels = sorted({r["label"] for r in records})
    fig, ax = plt.subplots(figsize=(min(12, max(6, 0.6 * len(labels) * len(tasks))), 4))
    w = 0.8 / len(labels)
    for j, label in enumerate(labels):
        ys, errs = [], [[], []]
        for t in tasks:
            recs = [r for r in records if r["task"] == t and r["label"] == label]
            k, n = sum(r["success"] for r in recs), len(recs)
            p = k / n if n else np.nan
            lo, hi = wilson_interval(k, n) if n else (np.nan, np.nan)
            ys.append(p)
            errs[0].append(max(p - lo, 0.0))  # float round-off at 0 / n and n / n
            errs[1].append(max(hi - p, 0.0))
        ax.bar(np.arange(len(tasks)) + j * w, ys, w, yerr=errs, label=label, capsize=2)
    ax.set_xticks(np.arange(len(tasks)) + 0.4 - w / 2, tasks)
    ax.set_ylabel("success (95% Wilson)")
    ax.set_ylim(0, 1.05)
    ax.legend(fontsize=7, ncol=2)
    return _save(fig, out / "success_per_agent.png")


def success_vs_tilt(records: list[dict], out: Path) -> Path:
    recs = [r for r in records if r["task"].startswith("PegInsert6DoF")]
    bins = np.arange(0, 55, 10)
    fig, ax = plt.subplots(figsize=(6, 4))
    for label in sorted({r["label"] for r in recs}):
        tilt = np.array([r["tilt_deg"] for r in recs if r["label"] == label])
        ok = np.array([r["success"] for r in recs if r["label"] == label], dtype=float)
        idx = np.digitize(tilt, bins) - 1
        ys = [ok[idx == b].mean() if np.any(idx == b) else np.nan for b in range(len(bins) - 1)]
        ax.plot(bins[:-1] + 5, ys, marker="o", label=label)
    ax.set_xlabel("hole tilt from vertical (deg)")
    ax.set_ylabel("success")
    ax.set_ylim(0, 1.05)
    ax.set_title("6-DoF: success vs tilt")
    ax.legend(fontsize=7)
    return _save(fig, out / "success_vs_tilt.png")


def servo_times(records: list[dict], out: Path) -> Path:
    labels = sorted({r["label"] for r in records})
    data = [
        [r["servo_time_s"] for r in records if r["label"] == lb and r["success"]] for lb in labels
    ]
    fig, ax = plt.subplots(figsize=(max(6, 0.8 * len(labels)), 4))
    ax.boxplot([d if d else [np.nan] for d in data], tick_labels=labels)
    ax.set_ylabel("simulated servo time of successes (s)")
    ax.tick_params(axis="x", labelrotation=45)
    return _save(fig, out / "servo_time.png")
