"""The closed-loop residual: how far the peg is from the true pre-insertion pose after each
of an agent's moves (records' `move_residuals`), per move, per sensor profile."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np

from cfvs_maniskill.report.plots import _save, plt

MAX_MOVES = 9
"""Moves shown (CFVS: 1 coarse + up to 8 fine)."""


def _by_move(records: list[dict]) -> dict[tuple, list[list[float]]]:
    cells: dict[tuple, list[list[float]]] = defaultdict(list)
    for r in records:
        for k, res in enumerate(r.get("move_residuals", [])[:MAX_MOVES], start=1):
            cells[(r["task"], r["label"], r["sensor"], k)].append(res)
    return cells


def table(records: list[dict]) -> str:
    """Per task, agent, sensor and move: lateral and tilt error, median and p90."""
    cells = _by_move(records)
    if not cells:
        return "No records with move residuals (recorded since the residuals were added)."
    out = [
        "| task | agent | sensor | move | episodes | lateral mm, median / p90 | "
        "tilt deg, median / p90 |",
        "|---|---|---|---|---|---|---|",
    ]
    for (task, label, sensor, k), res in sorted(cells.items()):
        a = np.asarray(res)
        lat, tilt = np.percentile(a[:, 0], [50, 90]), np.percentile(a[:, 1], [50, 90])
        out.append(
            f"| {task} | {label} | {sensor} | {k} | {len(a)} | {lat[0]:.1f} / {lat[1]:.1f} | "
            f"{tilt[0]:.1f} / {tilt[1]:.1f} |"
        )
    return "\n".join(out)


def plot(records: list[dict], out: Path, agent: str = "cfvs") -> Path | None:
    """p90 lateral and tilt error after each move of `agent`, one line per task x sensor."""
    cells = _by_move([r for r in records if r["label"] == agent])
    if not cells:
        return None
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for task, sensor in sorted({(t, s) for t, _, s, _ in cells}):
        moves = sorted(k for t, _, s, k in cells if (t, s) == (task, sensor))
        p90 = np.array(
            [np.percentile(np.asarray(cells[(task, agent, sensor, k)]), 90, axis=0) for k in moves]
        )
        for ax, col in zip(axes, (0, 1), strict=True):
            ax.plot(moves, p90[:, col], marker="o", label=f"{task} {sensor}")
    for ax, what in zip(axes, ("lateral error p90, mm", "tilt error p90, deg"), strict=True):
        ax.set_xlabel("move (1 = coarse, then fine iterations)")
        ax.set_ylabel(what)
        ax.axhline(1.0, color="grey", lw=0.8, ls="--")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle(f"{agent}: closed-loop residual after each move")
    return _save(fig, out / "residuals.png")
