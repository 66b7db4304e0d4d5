"""Train OAKN or the fine network on CPU: `python -m cfvs_maniskill.policies.cfvs.train --net oakn|opnv|opn --data FILE...`.

Resumable: the full training state is saved after every epoch to OUT.resume; a restarted
run with the same arguments continues from the last finished epoch. At the end OUT holds
the weights with their config, data hash, validation metrics and wall time, and
OUT.json the same metadata for people.
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
import tyro
from tqdm import tqdm

from cfvs_maniskill.data.augment import AugmentConfig, augment
from cfvs_maniskill.data.store import DatasetError, load_sets
from cfvs_maniskill.nets.checkpoint import (
    WeightsError,
    file_sha256,
    safe_load,
    save_atomic,
    write_weights,
)
from cfvs_maniskill.nets.pointnet2 import seed_sampling
from cfvs_maniskill.perception import labels as L
from cfvs_maniskill.policies.cfvs.oakn import OAKNConfig, oakn_loss, weighted_keypoints
from cfvs_maniskill.policies.cfvs.opn import OPNConfig, opn_loss
from cfvs_maniskill.policies.networks import build, load_weights


@dataclass
class TrainArgs:
    """Train a CFVS network (OAKN on a coarse dataset, OPN on a fine one) on the CPU."""

    net: str = "oakn"
    """oakn (coarse keypoints), opnv (fine stage by keypoint voting, shipped) or opn (the
    paper's fine stage: global feature -> offsets)."""
    data: tuple[Path, ...] = (Path("data/coarse.h5"),)
    """Dataset file(s) from `python -m cfvs_maniskill.data collect`, one kind and peg; several
    (e.g. the same task collected with different `--sensor` profiles) are trained on as one
    set, each file's tail held out for validation."""
    out: Path = Path("agents/cfvs/oakn.pt")
    """Weights file to write."""
    epochs: int = 12
    batch: int = 16
    lr: float = 2e-3
    weight_decay: float = 1e-4
    points: int = 0
    """Points per cloud fed to the net (a fresh random subset each time); 0: 512 for oakn,
    1024 for opn."""
    augment: bool = True
    """The paper's scaling / bending augmentation, on the fly (--no-augment: ablation)."""
    val_fraction: float = 0.05
    """The last samples of the file, held out for validation metrics."""
    threads: int = 0
    """torch threads (0: all cores)."""
    seed: int = 0
    max_minutes: float = 0.0
    """Stop (resumably) after this much wall time; 0 = no limit."""
    init: Path | None = None
    """Start from these weights (same net kind and config) instead of random ones: fine-tune
    on new data (e.g. more sensors or bodies) with fewer epochs."""


VOTING = ("oakn", "opnv")
"""Nets that vote keypoints per point (trained with the OAKN loss)."""
OPNV_CONFIG = OAKNConfig(sa1_radii=(0.015,), sa2_radius=0.04)
"""The fine crop is 16 cm across: smaller balls than OAKN's 3 / 8 cm."""


def _points_default(args: TrainArgs) -> int:
    return args.points or (1024 if args.net == "opn" else 512)


class Batches:
    """Samples -> tensors, with random point subsets and augmentation when training."""

    def __init__(
        self, data: dict, net: str, n_points: int, sigma: float, aug: AugmentConfig | None
    ):
        self.d, self.net, self.n, self.sigma, self.aug = data, net, n_points, sigma, aug

    def make(self, idx: np.ndarray, rng: np.random.Generator) -> dict[str, torch.Tensor]:
        pts = []
        keys = self.d["keypoints"][idx] if self.net in VOTING else None
        for j, i in enumerate(idx):
            p = self.d["points"][i]
            sel = rng.choice(len(p), self.n, replace=len(p) < self.n)
            p = p[sel]
            if self.aug is not None:
                k = keys[j] if keys is not None else L.fine_keypoints(self.d["action"][i])
                p, _ = augment(p, k, rng, self.aug)
            pts.append(p)
        out = {"points": torch.from_numpy(np.stack(pts).astype(np.float32))}
        if self.net in VOTING:
            k = torch.from_numpy(keys.astype(np.float32))
            x = out["points"]
            out["keypoints"] = k
            out["offsets"] = k[:, None, :, :] - x[:, :, None, :]
            out["confidence"] = torch.exp(-((x - k[:, None, 0]) ** 2).sum(-1) / (2 * self.sigma**2))
        else:
            out["action"] = torch.from_numpy(self.d["action"][idx].astype(np.float32))
        return out


def resume_state(args, sha, free: tuple[str, ...]) -> tuple[Path, dict, dict | None]:
    """(OUT.resume path, the run's key, the saved state or None). The key is every argument
    but the `free` ones (e.g. --max-minutes); a state saved by another run -> DatasetError."""
    path = args.out.with_name(args.out.name + ".resume")
    key = {k: str(v) for k, v in dataclasses.asdict(args).items() if k not in free}
    if not path.exists():
        return path, key, None
    blob = safe_load(path, DatasetError)
    if not isinstance(blob, dict) or "run_key" not in blob:
        raise DatasetError(
            f"{path}: not a resume state of this trainer; delete it or use another --out"
        )
    if blob["run_key"] != key or blob["data_sha256"] != sha:
        raise DatasetError(
            f"{path}: a resume state from other arguments or data; delete it or use another --out"
        )
    return path, key, blob


def update(opt, sched, loss: torch.Tensor, parts: dict, bar=None) -> None:
    """One optimiser + schedule step; show the losses on the progress bar if given."""
    opt.zero_grad()
    loss.backward()
    opt.step()
    sched.step()
    if bar is not None:
        bar.set_postfix(loss=f"{loss.item():.3f}", **{k: f"{v:.3f}" for k, v in parts.items()})


def _angle_deg(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    cos = torch.nn.functional.cosine_similarity(a, b, dim=-1).clamp(-1, 1)
    return torch.rad2deg(torch.acos(cos))


@torch.no_grad()
def validate(model, batches: Batches, idx: np.ndarray, net: str) -> dict[str, float]:
    model.eval()
    rng = np.random.default_rng(123)
    errs: dict[str, list[np.ndarray]] = {}
    for a in range(0, len(idx), 32):
        b = batches.make(idx[a : a + 32], rng)
        if net in VOTING:
            off, logit = model(b["points"])
            k, _ = weighted_keypoints(b["points"], off, torch.sigmoid(logit))
            gt = b["keypoints"]
            if net == "opnv":  # the offsets the agent would command, vs the labels
                acts = [L.fine_action_from_keypoints(x.numpy()) for x in k]
                pred = torch.from_numpy(np.stack(acts).astype(np.float32))
                want = torch.from_numpy(
                    np.stack([L.fine_action_from_keypoints(x.numpy()) for x in gt])
                )
                e_act = {
                    "dt_mm": 1000 * (pred[:, :3] - want[:, :3]).norm(dim=-1),
                    "dr_deg": torch.rad2deg((pred[:, 3:] - want[:, 3:]).norm(dim=-1)),
                    "dt_zero_mm": 1000 * want[:, :3].norm(dim=-1),
                }
            e = {
                "k1_mm": 1000 * (k[:, 0] - gt[:, 0]).norm(dim=-1),
                "axis_deg": _angle_deg(k[:, 2] - k[:, 0], gt[:, 2] - gt[:, 0]),
                "xdir_deg": _angle_deg(k[:, 1] - k[:, 0], gt[:, 1] - gt[:, 0]),
            }
            if net == "opnv":
                e.update(e_act)
        else:
            pred, gt = model(b["points"]), b["action"]
            e = {
                "dt_mm": 1000 * (pred[:, :3] - gt[:, :3]).norm(dim=-1),
                "dr_deg": torch.rad2deg((pred[:, 3:] - gt[:, 3:]).norm(dim=-1)),
                "dt_zero_mm": 1000 * gt[:, :3].norm(dim=-1),
            }
        for key, v in e.items():
            errs.setdefault(key, []).append(v.numpy())
    model.train()
    out = {}
    for key, v in errs.items():
        v = np.concatenate(v)
        out[f"{key}_mean"] = float(v.mean())
        out[f"{key}_p90"] = float(np.percentile(v, 90))
    return out


def train(args: TrainArgs) -> dict:
    if args.net not in ("oakn", "opnv", "opn"):
        raise DatasetError(f"--net: expected oakn, opnv or opn, got {args.net!r}")
    if args.threads:
        torch.set_num_threads(args.threads)
    kind = "coarse" if args.net == "oakn" else "fine"
    fields = ("points", "keypoints") if args.net == "oakn" else ("points", "action")
    sets = load_sets(args.data, fields, kind, args.net, args.val_fraction)
    data, attrs = sets.data, sets.attrs[0]
    if args.net == "opnv":
        # Keypoints of the pre-insertion target, k2 encoded for the square's symmetry.
        data["keypoints"] = np.stack(
            [L.encode_symmetric_x(L.fine_keypoints(a)) for a in data["action"]]
        )
    data_record = sets.record(file_sha256)
    sha = data_record["data_sha256"]
    train_idx, val_idx = sets.train_idx, sets.val_idx
    n_points = _points_default(args)
    net_cfg = {"oakn": OAKNConfig(), "opnv": OPNV_CONFIG, "opn": OPNConfig()}[args.net]
    batches = Batches(
        data,
        args.net,
        n_points,
        float(attrs["confidence_sigma"]),
        AugmentConfig() if args.augment else None,
    )
    torch.manual_seed(args.seed)
    seed_sampling(args.seed)
    model = build(args.net, dataclasses.asdict(net_cfg))
    if args.init is not None:
        start, start_meta = load_weights(args.init, args.net, sets.peg)
        if start_meta["config"] != dataclasses.asdict(net_cfg):
            raise DatasetError(
                f"{args.init}: field 'config': --init needs a {args.net} of config "
                f"{dataclasses.asdict(net_cfg)}, the file has {start_meta['config']}"
            )
        model.load_state_dict(start.state_dict())
    opt = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=args.weight_decay)
    steps_per_epoch = math.ceil(len(train_idx) / args.batch)
    sched = torch.optim.lr_scheduler.OneCycleLR(
        opt, max_lr=args.lr, total_steps=args.epochs * steps_per_epoch, pct_start=0.1
    )
    resume_path, run_key, blob = resume_state(args, sha, ("max_minutes", "threads"))
    state = {"epoch": 0, "history": [], "wall_s": 0.0}
    if blob is not None:
        model.load_state_dict(blob["state_dict"])
        opt.load_state_dict(blob["optimizer"])
        sched.load_state_dict(blob["scheduler"])
        state = blob["state"]
        print(f"resuming {args.out} after epoch {state['epoch']}")
    t_start = time.perf_counter() - state["wall_s"]
    t_session = time.perf_counter()
    model.train()
    for epoch in range(state["epoch"], args.epochs):
        rng = np.random.default_rng([args.seed, epoch])
        order = rng.permutation(train_idx)
        bar = tqdm(
            range(steps_per_epoch), desc=f"{args.net} epoch {epoch + 1}/{args.epochs}", unit="batch"
        )
        for s in bar:
            b = batches.make(order[s * args.batch : (s + 1) * args.batch], rng)
            if args.net in VOTING:
                off, logit = model(b["points"])
                loss, parts = oakn_loss(off, logit, b["offsets"], b["confidence"])
            else:
                loss, parts = opn_loss(model(b["points"]), b["action"])
            update(opt, sched, loss, parts, bar if s % 10 == 0 else None)
        metrics = validate(model, batches, val_idx, args.net)
        state = {
            "epoch": epoch + 1,
            "history": [*state["history"], {"epoch": epoch + 1, **metrics}],
            "wall_s": time.perf_counter() - t_start,
        }
        print(f"epoch {epoch + 1}: " + ", ".join(f"{k} {v:.2f}" for k, v in metrics.items()))
        save_atomic(
            {
                "run_key": run_key,
                "data_sha256": sha,
                "state_dict": model.state_dict(),
                "optimizer": opt.state_dict(),
                "scheduler": sched.state_dict(),
                "state": state,
            },
            resume_path,
        )
        if args.max_minutes and time.perf_counter() - t_session > 60 * args.max_minutes:
            print(f"stopped after {args.max_minutes} min; run the same command to resume")
            return state
    meta = {
        "net": args.net,
        "task": attrs["task"],
        "peg": attrs["peg"],
        "config": dataclasses.asdict(net_cfg),
        "points": n_points,
        **data_record,
        "init": None
        if args.init is None
        else {"path": str(args.init), "sha256": file_sha256(args.init)},
    }
    write_weights(
        args.out,
        model,
        meta,
        "cfvs_maniskill.policies.cfvs.train",
        args,
        state["history"],
        state["wall_s"],
    )
    resume_path.unlink(missing_ok=True)
    return state


def cli_main(args_type, train_fn, argv: list[str] | None = None) -> int:
    """Parse a training CLI, train; a bad dataset or argument -> message and exit code 2."""
    args = tyro.cli(args_type, args=argv)
    try:
        train_fn(args)
    except (DatasetError, WeightsError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


def main(argv: list[str] | None = None) -> int:
    return cli_main(TrainArgs, train, argv)


if __name__ == "__main__":
    sys.exit(main())
