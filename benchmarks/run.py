"""Every speed figure in one run: `python -m benchmarks.run` (or `make bench`).

Prints the figure table and rewrites benchmarks/RESULTS.md with the machine, date and
commit. Figures are ratios measured in the same run (these machines are noisy).
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass

import tyro

from benchmarks.common import RESULTS, Figure, commit, machine


@dataclass
class BenchArgs:
    """Measure all benchmark figures and rewrite benchmarks/RESULTS.md."""

    episodes: int = 30
    """CFVS 6-DoF episodes timed for the render + physics ratio (10 gave a spread of
    +-0.05 run to run, as large as the distance to the target)."""
    servo_episodes: int = 20
    """CFVS 3-DoF episodes per initial error for the servo time."""
    eval_per_object: int = 40
    """Episodes per test object in each eval-throughput run."""
    ray: bool = True
    """Include the Ray cluster figure (needs `pip install '.[ray]'`)."""


def main(args: BenchArgs) -> int:
    import cfvs_maniskill  # noqa: F401  (registers the env ids)
    from benchmarks import cfvs_speed, env_step, eval_scaling, sensing, servo_time, startup, video

    t0 = time.perf_counter()
    sections: list[tuple[str, str]] = []
    figures: list[Figure] = []

    def add(title: str, result: tuple[list[Figure], str]) -> None:
        figs, detail = result
        figures.extend(figs)
        sections.append((title, detail))
        for f in figs:
            print(f.row(), flush=True)

    add("Env step against ManiSkill", env_step.step_ratio())
    add("Point-cloud observation against a bare SAPIEN scene", env_step.pointcloud_floor())
    add("Stereo sensor models against the ideal one", sensing.overhead())
    add("CFVS episode and networks", cfvs_speed.measure(cfvs_speed.Args(episodes=args.episodes)))
    add("Servo time", servo_time.measure(args.servo_episodes))
    add("Episode videos", video.measure())
    add(
        "Evaluation throughput and memory",
        eval_scaling.measure(args.eval_per_object, ray_nodes=2 if args.ray else 0),
    )
    add("Start-up", startup.measure())
    table = [
        "| figure | measured | target | | note |",
        "|---|---|---|---|---|",
        *[f.row() for f in figures],
    ]
    text = [
        "# Benchmark results",
        "",
        f"`python -m benchmarks.run`: {time.strftime('%Y-%m-%d %H:%M')}, commit {commit()}, "
        f"{(time.perf_counter() - t0) / 60:.0f} min.",
        f"Machine: {machine()}.",
        "",
        *table,
    ]
    for title, detail in sections:
        text += ["", f"## {title}", "", detail]
    RESULTS.write_text("\n".join(text) + "\n")
    print(f"wrote {RESULTS}")
    return 0


if __name__ == "__main__":
    sys.exit(main(tyro.cli(BenchArgs)))
