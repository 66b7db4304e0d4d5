"""Train the KOVIS baseline on CPU: `python -m cfvs_maniskill.train_kovis --data FILE ...`.

Data: `python -m cfvs_maniskill.data collect --kind kovis` files (several may be mixed,
e.g. the 4-DoF and 6-DoF square-peg sets). Writes OUT (weights + config + data hashes +
validation metrics + wall time) and OUT.json (the same metadata for people).
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from cfvs_maniskill.data.store import DatasetError, load_sets
from cfvs_maniskill.nets.checkpoint import file_sha256, write_weights
from cfvs_maniskill.nets.kovis import KOVIS, KOVISConfig, kovis_loss, motion_targets
from cfvs_maniskill.perception.images import DEPTH_RANGE
from cfvs_maniskill.train import cli_main, update


@dataclass
class TrainKOVISArgs:
    """Train KOVIS (keypoint encoder + depth decoder + servo converter) jointly on CPU."""

    data: tuple[Path, ...] = (Path("data/kovis.h5"),)
    """One or more `--kind kovis` dataset files (same peg)."""
    out: Path = Path("agents/kovis/square.pt")
    """Weights file to write."""
    dof: int = 6
    """Motion dimensions the converter outputs: 3 (x y z), 4 (+ yaw) or 6."""
    epochs: int = 10
    batch: int = 64
    lr: float = 2e-3
    weight_decay: float = 1e-4
    noise: float = 4.0
    """Gray-level noise std added to training images (KOVIS trains with image noise)."""
    val_fraction: float = 0.05
    """The last samples of each file, held out for validation metrics."""
    threads: int = 0
    """torch threads (0: all cores)."""
    seed: int = 0


def depth_target(depth: np.ndarray) -> torch.Tensor:
    """(B, S, S) metres -> (B, S/2, S/2) in [0, 1], the decoder's target."""
    d = torch.from_numpy(depth.astype(np.float32))[:, None]
    d = F.avg_pool2d(d, 2)[:, 0]
    return (d - DEPTH_RANGE[0]) / (DEPTH_RANGE[1] - DEPTH_RANGE[0])


@torch.no_grad()
def validate(model: KOVIS, val: dict) -> dict[str, float]:
    model.eval()
    dirs, speeds, depths = [], [], []
    for a in range(0, len(val["action"]), 128):
        g = torch.from_numpy(val["gray"][a : a + 128])
        act = torch.from_numpy(val["action"][a : a + 128].astype(np.float32))
        _, depth, direction, speed = model(g)
        want_dir, want_speed = motion_targets(act, model.cfg)
        cos = F.cosine_similarity(direction, want_dir, dim=-1).clamp(-1, 1)
        far = want_speed > 0.1  # the direction of a tiny offset is mostly noise
        dirs.append(torch.rad2deg(torch.acos(cos[far])).numpy())
        speeds.append((torch.sigmoid(speed) - want_speed).abs().numpy())
        t = depth_target(val["depth"][a : a + 128])
        depths.append(
            (depth[:, 0] - t).abs().mean((1, 2)).numpy() * (DEPTH_RANGE[1] - DEPTH_RANGE[0])
        )
    model.train()
    d, s, z = (np.concatenate(x) for x in (dirs, speeds, depths))
    return {
        "direction_err_deg_mean": float(d.mean()),
        "direction_err_deg_p90": float(np.percentile(d, 90)),
        "speed_abs_err_mean": float(s.mean()),
        "depth_err_mm_mean": float(1000 * z.mean()),
    }


def train(args: TrainKOVISArgs) -> dict:
    if args.dof not in (3, 4, 6):
        raise DatasetError(f"--dof: expected 3, 4 or 6, got {args.dof}")
    if args.threads:
        torch.set_num_threads(args.threads)
    sets = load_sets(args.data, ("gray", "depth", "action"), "kovis", "KOVIS")
    val = {k: v[sets.val_idx] for k, v in sets.data.items()}
    data = {k: v[sets.train_idx] for k, v in sets.data.items()}
    cfg = KOVISConfig(motion_dims=args.dof)
    torch.manual_seed(args.seed)
    model = KOVIS(cfg)
    opt = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=args.weight_decay)
    m = len(data["action"])
    steps = math.ceil(m / args.batch)
    sched = torch.optim.lr_scheduler.OneCycleLR(
        opt, max_lr=args.lr, total_steps=args.epochs * steps, pct_start=0.1
    )
    history, t0 = [], time.perf_counter()
    for epoch in range(args.epochs):
        rng = np.random.default_rng([args.seed, epoch])
        order = rng.permutation(m)
        bar = tqdm(range(steps), desc=f"kovis epoch {epoch + 1}/{args.epochs}", unit="batch")
        for s in bar:
            idx = np.sort(order[s * args.batch : (s + 1) * args.batch])
            gray = data["gray"][idx].astype(np.float32)
            gray += rng.normal(0, args.noise, gray.shape).astype(np.float32)
            gray = torch.from_numpy(gray.clip(0, 255))
            act = torch.from_numpy(data["action"][idx].astype(np.float32))
            loss, parts = kovis_loss(model(gray), depth_target(data["depth"][idx]), act, cfg)
            update(opt, sched, loss, parts, bar if s % 10 == 0 else None)
        metrics = validate(model, val)
        history.append({"epoch": epoch + 1, **metrics})
        print(f"epoch {epoch + 1}: " + ", ".join(f"{k} {v:.3f}" for k, v in metrics.items()))
    wall = time.perf_counter() - t0
    meta = {
        "net": "kovis",
        "task": ",".join(str(p) for p in args.data),
        "peg": sets.peg,
        "config": dataclasses.asdict(cfg),
        **sets.record(file_sha256),
    }
    meta = write_weights(args.out, model, meta, "cfvs_maniskill.train_kovis", args, history, wall)
    return meta


def main(argv: list[str] | None = None) -> int:
    return cli_main(TrainKOVISArgs, train, argv)


if __name__ == "__main__":
    sys.exit(main())
