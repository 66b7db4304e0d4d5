"""Where KOVIS's servo loses precision, measured in closed loop:
`python -m cfvs_maniskill.policies.kovis.diagnose --task PegInsert3DoF --episodes 20`.

Runs the shipped KOVIS on the unseen test objects and, at every decision, compares what
the network says with the truth the simulator knows (read here for the diagnosis only; the
agent never sees it): the direction error against the true motion to the pre-insertion
pose, binned by the distance still to go; the distance the speed implies
(-ln(1 - s) / a_dist) against the true one; and where the servo stopped (the distance to
the goal when it declared arrival or ran out of steps). Writes OUT/diagnosis.json and
OUT/diagnosis.md.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import tyro
from tqdm import tqdm

BINS = (0.0, 0.005, 0.02, 0.05, 0.1, 1.0)
"""Distance-to-goal bins, m."""


@dataclass
class DiagnoseArgs:
    """Closed-loop diagnosis of the KOVIS servo against the simulator's truth."""

    task: str = "PegInsert3DoF"
    episodes: int = 20
    """Episodes per initial distance (15 and 30 cm)."""
    sensor: str = "ideal"
    out: Path = Path("results/kovis_diagnosis")
    seed: int = 9000


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    c = float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b) + 1e-12))
    return float(np.degrees(np.arccos(np.clip(c, -1, 1))))


def diagnose(args: DiagnoseArgs) -> dict:
    import torch

    from cfvs_maniskill.constants import PRE_INSERT_HEIGHT
    from cfvs_maniskill.control.executor import Executor
    from cfvs_maniskill.nets.checkpoint import file_sha256
    from cfvs_maniskill.perception import labels as L
    from cfvs_maniskill.policies.interface import TaskSpec
    from cfvs_maniskill.policies.kovis.agent import KOVISAgent
    from cfvs_maniskill.policies.kovis.model import MOTION_DIMS, implied_distance
    from cfvs_maniskill.provenance import file_key
    from cfvs_maniskill.session import Session, make_env
    from cfvs_maniskill.task_dof import constrain

    torch.set_num_threads(1)
    env = make_env(args.task, "kovis", objects=["test"], sensor=args.sensor)
    u = env.unwrapped
    rows: list[dict] = []

    class Probe(KOVISAgent):
        """KOVIS, with each decision's output logged beside the truth."""

        episode = 0

        def motion(self, obs):
            action, s = super().motion(obs)
            tcp = u.tcp_matrix()
            goal = constrain(
                self.task, u.insertion_pose(-PRE_INSERT_HEIGHT, u.hole_pose, tcp), ref=tcp
            )
            true = L.fine_action(tcp, goal)
            dims = MOTION_DIMS[self.task.dof]
            rows.append(
                {
                    "episode": self.episode,
                    "distance": float(np.linalg.norm(true[:3])),
                    "implied": implied_distance(s, self.net.cfg),
                    "direction_err_deg": _angle(action[dims], true[dims]),
                }
            )
            return action, s

    agent = Probe(TaskSpec.of_env(env))
    weights = agent.cfg.weights_dir / f"{agent.task.peg}.pt"
    session = Session(env, agent, Executor(env))  # the probe, not a registry agent
    episodes = []
    for init in ("small", "large"):
        u.init_error_m = u.task.init_error[init]
        for i in tqdm(range(args.episodes), desc=f"kovis diagnosis {init}", unit="episode"):
            agent.episode = len(episodes)
            n0 = len(rows)
            r = session.episode(args.seed + i)
            last = rows[-1] if len(rows) > n0 else None
            episodes.append(
                {
                    "init": init,
                    "success": r.success,
                    "decisions": len(rows) - n0,
                    "stop_distance_mm": None if last is None else 1000 * last["distance"],
                    "final_lateral_mm": 1000 * r.lateral_offset_m,
                }
            )
    env.close()
    d = np.array([r["distance"] for r in rows])
    err = np.array([r["direction_err_deg"] for r in rows])
    implied = np.array([r["implied"] for r in rows])
    bins = []
    for lo, hi in zip(BINS[:-1], BINS[1:], strict=True):
        m = (d >= lo) & (d < hi)
        bins.append(
            {
                "distance_mm": [1000 * lo, 1000 * hi],
                "decisions": int(m.sum()),
                "direction_err_deg_median": float(np.median(err[m])) if m.any() else None,
                "implied_minus_true_mm_median": float(1000 * np.median(implied[m] - d[m]))
                if m.any()
                else None,
            }
        )
    stops = [e["stop_distance_mm"] for e in episodes if e["stop_distance_mm"] is not None]
    out = {
        "task": args.task,
        "sensor": args.sensor,
        "weights": file_key(weights),
        "weights_sha256": file_sha256(weights),
        "episodes": episodes,
        "success": {
            i: float(np.mean([e["success"] for e in episodes if e["init"] == i]))
            for i in ("small", "large")
        },
        "bins": bins,
        "stop_distance_mm_median": float(np.median(stops)) if stops else None,
        "stop_distance_mm_p90": float(np.percentile(stops, 90)) if stops else None,
        "command": "python -m cfvs_maniskill.policies.kovis.diagnose " + " ".join(sys.argv[1:]),
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "diagnosis.json").write_text(json.dumps(out, indent=1))
    lines = [
        f"# KOVIS closed-loop diagnosis: {args.task}, `{args.sensor}`",
        "",
        f"`{out['command']}`; success 15 / 30 cm: {out['success']['small']:.2f} / "
        f"{out['success']['large']:.2f}; where the servo stopped (distance to the goal): "
        f"median {out['stop_distance_mm_median']:.1f} mm, p90 {out['stop_distance_mm_p90']:.1f} mm.",
        "",
        "| distance to go | decisions | direction error (median) | implied - true distance (median) |",
        "|---|---|---|---|",
    ]
    for b in bins:
        if b["decisions"]:
            lines.append(
                f"| {b['distance_mm'][0]:.0f}-{b['distance_mm'][1]:.0f} mm | {b['decisions']} | "
                f"{b['direction_err_deg_median']:.1f} deg | {b['implied_minus_true_mm_median']:+.1f} mm |"
            )
    (args.out / "diagnosis.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return out


def main(argv: list[str] | None = None) -> int:
    diagnose(tyro.cli(DiagnoseArgs, args=argv))
    return 0


if __name__ == "__main__":
    sys.exit(main())
