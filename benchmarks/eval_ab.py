"""Evaluation throughput of two versions of the code, interleaved: `python -m benchmarks.eval_ab
--base REV` runs the same small evaluation from a checkout of REV and from this one, in
turns, and writes the rates to benchmarks/EVAL_AB.md. Interleaving matters: on these
machines the rate moves by tens of percent from one hour to the next, far more than a change
of the orchestration does."""

from __future__ import annotations

import re
import statistics
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import tyro
from tqdm import tqdm

from benchmarks.common import machine

ROOT = Path(__file__).resolve().parent.parent
OUT = Path(__file__).parent / "EVAL_AB.md"
RATE = re.compile(r"\(([\d.]+) episodes/s; ([\d.]+) episodes/s once every worker had started\)")


@dataclass
class Args:
    """Compare the evaluation's episodes per second at REV and at this checkout."""

    base: str = "HEAD~1"
    """The git revision to compare against (a worktree of it is made in a temporary folder)."""
    rounds: int = 3
    """Runs of each side, alternating."""
    eval_args: tuple[str, ...] = (
        "--tasks", "PegInsert3DoF", "PegInsert6DoF", "--agents", "cfvs", "oracle",
        "--objects", "test", "--init-errors", "small", "--episodes-per-object", "6",
        "--workers", "2",
    )  # fmt: skip
    """The evaluation both sides run (`--out` is added)."""


def _rate(checkout: Path, eval_args: tuple[str, ...], out: Path) -> tuple[float, float]:
    r = subprocess.run(
        [sys.executable, "-m", "cfvs_maniskill.eval", *eval_args, "--out", str(out)],
        cwd=checkout, capture_output=True, text=True, check=True,
    )  # fmt: skip
    m = RATE.search(r.stdout)
    if m is None:
        raise RuntimeError(f"no rate in the eval's output:\n{r.stdout[-2000:]}")
    return float(m.group(1)), float(m.group(2))


def main(args: Args) -> int:
    rev = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--short=12", args.base],
        capture_output=True, text=True, check=True,
    ).stdout.strip()  # fmt: skip
    head = subprocess.run(
        ["git", "-C", str(ROOT), "describe", "--always", "--dirty", "--abbrev=12"],
        capture_output=True, text=True, check=True,
    ).stdout.strip()  # fmt: skip
    rates: dict[str, list[tuple[float, float]]] = {"base": [], "this": []}
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp) / "base"
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "add", "--detach", str(base), rev],
            capture_output=True, check=True,
        )  # fmt: skip
        try:
            runs = [(side, i) for i in range(args.rounds) for side in ("base", "this")]
            for side, i in tqdm(runs, desc="eval A/B", unit="run"):
                checkout = base if side == "base" else ROOT
                rates[side].append(_rate(checkout, args.eval_args, Path(tmp) / f"{side}{i}"))
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(base)])
    mean = {s: [statistics.mean(r[k] for r in v) for k in (0, 1)] for s, v in rates.items()}
    ratio = [mean["this"][k] / mean["base"][k] for k in (0, 1)]
    rows = [
        f"| {s} | " + ", ".join(f"{a:.2f}" for a, _ in v) + f" | {mean[s][0]:.2f} | "
        + ", ".join(f"{b:.2f}" for _, b in v) + f" | {mean[s][1]:.2f} |"
        for s, v in rates.items()
    ]  # fmt: skip
    text = "\n".join(
        [
            "# Evaluation throughput, A/B",
            "",
            f"`python -m benchmarks.eval_ab --base {args.base}`: {rev} (base) against {head}"
            f" (this), {args.rounds} runs each, alternating; {machine()}.",
            f"Each run: `eval {' '.join(args.eval_args)}`.",
            "",
            "| side | episodes/s, each run | mean | once every worker had started | mean |",
            "|---|---|---|---|---|",
            *rows,
            "",
            f"this / base: {ratio[0]:.3f} overall, {ratio[1]:.3f} once every worker had started.",
            "",
        ]
    )
    OUT.write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main(tyro.cli(Args)))
