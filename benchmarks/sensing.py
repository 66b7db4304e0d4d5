"""The stereo sensor models' cost: a point-cloud observation under each stereo profile
against `ideal` (same task, same scene), interleaved so all see the same machine load.
Target: at most 1.3x the ideal profile's time per observation (the D405 profiles render a
wider 87 x 58 deg camera at the same angular resolution, and run the texture, occlusion and
calibration model on it)."""

from __future__ import annotations

from benchmarks.common import Figure, interleaved

PROFILES = ("realistic", "textured", "d435")
TARGET = 1.30


def overhead(calls: int = 20, rounds: int = 8) -> tuple[list[Figure], str]:
    import gymnasium as gym

    envs = {
        s: gym.make("PegInsert6DoF-v1", obs_mode="pointcloud", sensor=s)
        for s in ("ideal", *PROFILES)
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
    sizes = {s: "x".join(map(str, e.unwrapped.camera_geometry[:2])) for s, e in envs.items()}
    for e in envs.values():
        e.close()
    figs = [
        Figure(
            f"{s} sensor / ideal, point-cloud observation",
            f"{ms[s] / ms['ideal']:.2f} ({ms[s]:.1f} / {ms['ideal']:.1f} ms)",
            f"<= {TARGET:.2f}",
            ms[s] / ms["ideal"] <= TARGET,
        )
        for s in PROFILES
    ]
    detail = (
        f"PegInsert6DoF-v1, {n} observations each, interleaved; wrist camera "
        + ", ".join(f"{s} {sizes[s]} px {ms[s]:.1f} ms" for s in ("ideal", *PROFILES))
        + " per observation."
    )
    return figs, detail


if __name__ == "__main__":
    import cfvs_maniskill  # noqa: F401

    figs, detail = overhead()
    for f in figs:
        print(f.row())
    print(detail)
