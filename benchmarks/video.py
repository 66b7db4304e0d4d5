"""What an episode video costs: CFVS 6-DoF episodes filmed (`rendering/film.py`, as
`run --video` and the report's videos), rendering + encoding time per video and per frame,
beside the same episodes unfilmed. Part of `python -m benchmarks.run`."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from benchmarks.common import Figure

SEEDS = (2000, 2001, 2002)
TARGET_S = 30.0
"""A video should cost at most this much on 2 CPU cores (the report renders dozens)."""


def measure(seeds: tuple[int, ...] = SEEDS) -> tuple[list[Figure], str]:
    import gymnasium as gym

    import cfvs_maniskill  # noqa: F401
    from cfvs_maniskill.control.executor import Executor
    from cfvs_maniskill.episode import run_episode
    from cfvs_maniskill.policies.registry import make_agent
    from cfvs_maniskill.rendering.film import Film

    env = gym.make("PegInsert6DoF-v1", obs_mode="pointcloud", objects=["test"])
    agent, ex = make_agent("cfvs", env), Executor(env)
    film = Film(env, "cfvs")
    run_episode(env, agent, ex, seed=seeds[0], film=film)  # warm-up: the lit shader's compile
    plain, filmed, frames, rendered = 0.0, 0.0, 0, 0
    with tempfile.TemporaryDirectory() as tmp:
        for s in seeds:
            t = time.perf_counter()
            run_episode(env, agent, ex, seed=s)
            plain += time.perf_counter() - t
            t = time.perf_counter()
            run_episode(env, agent, ex, seed=s, film=film)
            film.write(Path(tmp) / f"{s}.mp4")
            filmed += time.perf_counter() - t
            frames += len(film.frames)
            rendered += len(film.captions)  # the rest repeat the last frame
    env.close()
    n = len(seeds)
    per_video = (filmed - plain) / n
    detail = (
        f"{n} CFVS 6-DoF episodes (seeds {seeds[0]}-{seeds[-1]}, test objects), each run "
        f"unfilmed and filmed: {plain / n:.2f} s vs {filmed / n:.2f} s per episode; "
        f"{frames / n:.0f} frames per video (768 x 576: a 512 px lit close view, a 256 px "
        f"overview, the wrist depth and two caption lines; a frame per 0.1 s of robot time "
        f"plus 1.5 s held on the outcome), {1000 * per_video / (rendered / n):.0f} ms per "
        "rendered frame."
    )
    return [
        Figure(
            "episode video (CFVS 6-DoF): extra wall time per video",
            f"{per_video:.1f} s",
            f"<= {TARGET_S:.0f} s",
            per_video <= TARGET_S,
            f"{frames / n:.0f} frames",
        )
    ], detail


if __name__ == "__main__":
    figs, text = measure()
    print(text)
    print("\n".join(f.row() for f in figs))
