"""Shared pieces of the benchmarks: a figure record, an accumulating timer, interleaved
timing, and the commit and machine lines."""

from __future__ import annotations

import os
import platform
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

RESULTS = Path(__file__).parent / "RESULTS.md"


@dataclass
class Figure:
    """One line of the issue's figure table."""

    name: str
    value: str
    target: str
    met: bool | None
    """None: a figure to report, with no pass / fail target."""
    note: str = ""

    def row(self) -> str:
        verdict = {True: "met", False: "NOT met", None: "reported"}[self.met]
        return f"| {self.name} | {self.value} | {self.target} | {verdict} | {self.note} |"


class Timer:
    """Wraps a callable and accumulates its wall time."""

    def __init__(self, fn):
        self.fn, self.total, self.calls = fn, 0.0, 0

    def __call__(self, *a, **k):
        t = time.perf_counter()
        try:
            return self.fn(*a, **k)
        finally:
            self.total += time.perf_counter() - t
            self.calls += 1


def interleaved(fns: dict[str, callable], rounds: int) -> dict[str, float]:
    """Total seconds per function, calling them in turn `rounds` times, so that a noisy
    neighbour on the machine slows all of them alike (the figures are ratios)."""
    total = dict.fromkeys(fns, 0.0)
    for _ in range(rounds):
        for name, fn in fns.items():
            t = time.perf_counter()
            fn()
            total[name] += time.perf_counter() - t
    return total


def commit() -> str:
    r = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                           capture_output=True, text=True).stdout.strip()  # fmt: skip
    return r.stdout.strip() + ("+changes" if dirty else "")


def machine() -> str:
    import torch

    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    return (
        f"{cpu}, {os.cpu_count()} cores, {mem:.0f} GiB, no GPU (SwiftShader Vulkan), "
        f"Python {platform.python_version()}, torch {torch.__version__}"
    )
