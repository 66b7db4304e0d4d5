"""The realistic sensor model's cost: a point-cloud observation under `realistic` against
`ideal` (same task, same scene), interleaved so both see the same machine load. Target
: at most 20% more time per observation."""

from __future__ import annotations

from benchmarks.common import Figure, interleaved


def overhead(calls: int = 20, rounds: int = 8) -> tuple[list[Figure], str]:
    import gymnasium as gym

    envs = {
        s: gym.make("PegInsert6DoF-v1", obs_mode="pointcloud", sensor=s)
        for s in ("ideal", "realistic")
    }
    for e in envs.values():
        e.reset(seed=0)
        e.unwrapped.get_obs()  # warm up the renderer

    def observe(env):
        def f():
            for _ in range(calls):
                env.unwrapped.get_obs()

        return f

    t = interleaved({s: observe(e) for s, e in envs.items()}, rounds)
    n = calls * rounds
    ms = {s: 1000 * v / n for s, v in t.items()}
    ratio = ms["realistic"] / ms["ideal"]
    for e in envs.values():
        e.close()
    fig = Figure(
        "realistic sensor / ideal, point-cloud observation",
        f"{ratio:.2f} ({ms['realistic']:.1f} / {ms['ideal']:.1f} ms)",
        "<= 1.20",
        ratio <= 1.20,
    )
    detail = (
        f"PegInsert6DoF-v1, 128 x 128 wrist camera, {n} observations each, interleaved: "
        f"ideal {ms['ideal']:.1f} ms, realistic {ms['realistic']:.1f} ms per observation."
    )
    return [fig], detail


if __name__ == "__main__":
    import cfvs_maniskill  # noqa: F401

    figs, detail = overhead()
    print(figs[0].row())
    print(detail)
