"""The closed-loop residual: how far the peg is from the true pre-insertion pose after each
of an agent's moves (records' `move_residuals`), per move, per sensor profile, and after its
last move: where the insertion starts from."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np

from cfvs_maniskill.report import style
from cfvs_maniskill.report.plots import _save, plt
from cfvs_maniskill.sensing.floor import TABLE_VIEW_HEIGHT, floor_p90

MAX_MOVES = 9
"""Moves shown (CFVS: 1 coarse + up to 8 fine)."""


def _by_move(records: list[dict], last: bool = False) -> dict[tuple, list[list[float]]]:
    """Residuals per (task, agent, sensor, move); with `last`, also move "last" (each
    episode's last move, whichever number it had)."""
    cells: dict[tuple, list[list[float]]] = defaultdict(list)
    for r in records:
        moves = r.get("move_residuals", [])
        for k, res in enumerate(moves[:MAX_MOVES], start=1):
            cells[(r["task"], r["label"], r["sensor"], k)].append(res)
        if last and moves:
            cells[(r["task"], r["label"], r["sensor"], "last")].append(moves[-1])
    return cells


def table(records: list[dict]) -> str:
    """Per task, agent, sensor and move (then after the last move, before the insertion):
    lateral and tilt error, median and p90."""
    cells = _by_move(records, last=True)
    if not cells:
        return "No records with move residuals (recorded since the residuals were added)."
    out = [
        "| task | agent | sensor | move | episodes | lateral mm, median / p90 | "
        "tilt deg, median / p90 |",
        "|---|---|---|---|---|---|---|",
    ]
    for (task, label, sensor, k), res in sorted(cells.items(), key=_move_order):
        a = np.asarray(res)
        lat, tilt = np.percentile(a[:, 0], [50, 90]), np.percentile(a[:, 1], [50, 90])
        out.append(
            f"| {task} | {label} | {sensor} | {k} | {len(a)} | {lat[0]:.2f} / {lat[1]:.2f} | "
            f"{tilt[0]:.2f} / {tilt[1]:.2f} |"
        )
    notes = []
    for s in sorted({s for _, _, s, _ in cells}):
        if (f := floor_p90(s)) is not None:
            c = floor_p90(s, table_view_height=TABLE_VIEW_HEIGHT)
            notes.append(f"`{s}` {f[0]:.2f} mm / {f[1]:.2f} deg ({c[0]:.2f} / {c[1]:.2f})")
    if notes:
        out.append(
            "\nThe hand-eye floor, p90 lateral / tilt: where a perfect estimator of the hole "
            "ends when it trusts the nominal camera mount and the depth camera's calibration "
            "(in brackets: calibrated on the table, as CFVS is; `python -m "
            "cfvs_maniskill.sensing.floor`): " + ", ".join(notes) + "."
        )
    return "\n".join(out)


def _move_order(item: tuple) -> tuple:
    (task, label, sensor, k), _ = item
    return task, label, sensor, MAX_MOVES + 1 if k == "last" else k


def plot(records: list[dict], out: Path, agent: str = "cfvs") -> Path | None:
    """p90 lateral (top) and tilt (bottom) error after each move of `agent`: a column per
    sensor profile, a line per task (at most `style.MAX_LINES` per panel)."""
    cells = _by_move([r for r in records if r["label"] == agent])
    if not cells:
        return None
    sensors = sorted({s for _, _, s, _ in cells}, key=lambda s: (s != "ideal", s))
    tasks = sorted({t for t, _, _, _ in cells})[: style.MAX_LINES]
    colours = dict(zip(tasks, style.COLOURS + style.EXTRA_COLOURS, strict=False))
    fig, axes = plt.subplots(
        2, len(sensors), figsize=(4.2 * len(sensors), 6), squeeze=False, sharey="row"
    )
    for c, sensor in enumerate(sensors):
        for i, task in enumerate(tasks):
            moves = sorted(k for t, _, s, k in cells if (t, s) == (task, sensor))
            if not moves:
                continue
            p90 = np.array(
                [
                    np.percentile(np.asarray(cells[(task, agent, sensor, k)]), 90, axis=0)
                    for k in moves
                ]
            )
            for row in (0, 1):
                axes[row][c].plot(
                    moves, p90[:, row], color=colours[task], marker=style.MARKERS[i], label=task
                )
        for row, what in enumerate(("lateral error p90, mm", "tilt error p90, deg")):
            ax = axes[row][c]
            ax.axhline(1.0, color="grey", lw=0.8, ls="--")  # the 1 mm / 1 deg target
            floor = floor_p90(sensor)
            if floor is not None:  # no camera-only agent that trusts its mount gets below it
                calibrated = floor_p90(sensor, table_view_height=TABLE_VIEW_HEIGHT)
                lines = [
                    ax.axhline(floor[row], color="black", lw=0.8, ls=":"),
                    ax.axhline(calibrated[row], color="black", lw=0.8, ls="-."),
                ]
                if row == 0 and c > 0:
                    labels = ["hand-eye floor p90", "... calibrated on the table"]
                    ax.legend(handles=lines, labels=labels, fontsize=7)
            ax.grid(alpha=0.3)
            ax.set_ylabel(what)
            ax.set_xlabel("move (1 = coarse, then fine iterations)")
        axes[0][c].set_title(f"sensor: {sensor}", fontsize=9)
    axes[0][0].legend(fontsize=7)
    fig.suptitle(f"{agent}: closed-loop residual after each move")
    return _save(fig, out / "residuals.png")
