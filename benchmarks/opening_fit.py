"""How far the fine network's hole estimate and the opening fit land from the true opening,
on wrist views taken near the pre-insertion pose (the poses the fine loop visits).

Each view: a scene as the task samples it, the peg moved to the true pre-insertion pose
offset by a random fine-stage error (up to `--max-offset` mm, the task's tilt and yaw
limits), the wrist cloud rendered with the sensor profile; then the agent's OPN offset
(constrained to the task's DoF) gives the estimate, and perception/opening.fit_opening
moves it onto the opening seen. Lateral error = the estimate's distance from the true
axis. Written to `--out` as JSON (every view, and p50 / p90 of both).

    python -m benchmarks.opening_fit --task PegInsert3DoF --views 40 \
        --out results/opening_fit/3dof_ideal.json
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import tyro
from tqdm import tqdm


@dataclass
class Args:
    task: str = "PegInsert3DoF"
    """Task name (3-, 4- or 6-DoF; square or round peg)."""
    objects: list[str] = field(default_factory=lambda: ["test"])
    """Hole objects (names or splits) the scenes are drawn from."""
    assets: list[str] = field(default_factory=list)
    """Extra hole-object folders."""
    sensor: str = "ideal"
    """Sensor profile of the wrist camera."""
    views: int = 40
    """How many wrist views."""
    max_offset: float = 4.0
    """Largest lateral offset from the pre-insertion pose, mm."""
    seed: int = 0
    """View i is drawn from (seed, i)."""
    out: Path = Path("results/opening_fit/views.json")
    """JSON file written."""
    save_views: Path | None = None
    """Also save each view (points, estimate, true hole frame) as an .npz in this folder."""


def lateral_mm(F: np.ndarray, H: np.ndarray) -> float:
    """Distance of frame F's origin from the true hole frame H's axis, mm."""
    d = F[:3, 3] - H[:3, 3]
    z = H[:3, 2]
    return 1000.0 * float(np.linalg.norm(d - (d @ z) * z))


def main(args: Args) -> dict:
    import torch

    from cfvs_maniskill.constants import hole_half_extent
    from cfvs_maniskill.envs.lookup import find_task
    from cfvs_maniskill.perception import labels as L
    from cfvs_maniskill.perception.clouds import fine_crop, object_points, tool_to_world
    from cfvs_maniskill.perception.opening import fit_opening
    from cfvs_maniskill.policies.cfvs.agent import CFVSAgent
    from cfvs_maniskill.policies.cfvs.collect import fine_start
    from cfvs_maniskill.policies.cfvs.config import CFVSConfig
    from cfvs_maniskill.policies.interface import TaskSpec
    from cfvs_maniskill.session import make_env

    task = find_task(args.task)
    env = make_env(task, "cfvs", objects=args.objects, assets=args.assets, sensor=args.sensor)
    u = env.unwrapped
    spec = TaskSpec.of(task)
    # The estimate the fit starts from: OPN's, with the 6-DoF axis from the face.
    agent = CFVSAgent(spec, CFVSConfig(opening_fit=False))
    half = hole_half_extent(task.peg, task.clearance)
    rows = []
    for i in tqdm(range(args.views), desc="wrist views"):
        rng = np.random.default_rng([args.seed, i])
        agent.reset(int(rng.integers(2**31 - 1)))
        u.defer_obs = True
        try:
            env.reset(seed=int(rng.integers(2**31 - 1)))
        finally:
            u.defer_obs = False
        H = u.hole_pose.copy()
        q = fine_start(u, H, rng, args.max_offset / 1000.0, constrain=agent.constrain)
        if q is None:
            continue
        u.agent.reset(torch.as_tensor(q, dtype=torch.float32)[None])
        obs = u.get_obs()
        tcp = u.tcp_matrix()
        pts = object_points(obs["pointcloud"]["xyzw"][0].numpy(), tcp, task.peg)
        a = agent.predict_offset(fine_crop(pts))
        if a is None:
            continue
        a, _ = agent.refine(a, pts, tcp)
        E = L.hole_frame_from_pre_insertion(L.apply_action(tcp, a))
        world = tool_to_world(pts, tcp)
        F = fit_opening(world, E, half, round_opening=task.peg == "round")
        if args.save_views is not None:
            args.save_views.mkdir(parents=True, exist_ok=True)
            name = f"{u.episode_info['object']}_view_{i}.npz"
            np.savez_compressed(
                args.save_views / name,
                points=world.astype(np.float32),
                estimate=E,
                true_hole=H,
                half=half,
            )
        rows.append(
            {
                "view": i,
                "object": u.episode_info["object"],
                "start_mm": lateral_mm(L.hole_frame_from_pre_insertion(tcp), H),
                "opn_mm": lateral_mm(E, H),
                "fit_mm": None if F is None else lateral_mm(F, H),
            }
        )
    env.close()
    summary = _summary(rows)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(
        json.dumps(
            {"args": {k: str(v) for k, v in vars(args).items()}, "summary": summary, "views": rows},
            indent=1,
        )
    )
    print(json.dumps(summary, indent=1))
    return summary


def _summary(rows: list[dict]) -> dict:
    opn = np.array([r["opn_mm"] for r in rows])
    fitted = [r for r in rows if r["fit_mm"] is not None]
    fit = np.array([r["fit_mm"] for r in fitted])
    taken = np.array([r["fit_mm"] if r["fit_mm"] is not None else r["opn_mm"] for r in rows])
    pct = lambda x: [round(float(np.percentile(x, p)), 2) for p in (50, 90)] if len(x) else None  # noqa: E731
    return {
        "views": len(rows),
        "fitted": len(fitted),
        "opn_p50_p90_mm": pct(opn),
        "fit_p50_p90_mm_where_fitted": pct(fit),
        "opn_p50_p90_mm_where_fitted": pct(np.array([r["opn_mm"] for r in fitted])),
        "taken_p50_p90_mm": pct(taken),
    }


if __name__ == "__main__":
    main(tyro.cli(Args))
