"""Train the KOVIS baseline on CPU: `python -m cfvs_maniskill.policies.kovis.train --data FILE ...`.

Data: `python -m cfvs_maniskill.data collect --kind kovis` files (rollouts of stereo pairs;
several files of one peg may be mixed). As KOVIS's train_servo.py: encoder, decoder and
converter train jointly with Adam (amsgrad), its "repeat" cosine learning-rate schedule,
bootstrapped losses annealed from all to 30% of pixels / samples, the keypoint Gaussian
sharpened from sigma 1.0 to 2.5 over the first half, and its image augmentation (textured
backgrounds and objects, brightness, contrast, fractal noise).

Stops and resumes: the full training state (weights, optimiser, position in the epoch) is
saved to OUT.resume every `--checkpoint-minutes` and when `--max-minutes` is reached; the
same command continues from there, drawing the same batches and augmentations. Writes OUT
(weights + config + data hashes + validation metrics + wall time) and OUT.json at the end.
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
from cfvs_maniskill.nets.checkpoint import (
    WeightsError,
    file_sha256,
    save_atomic,
    write_weights,
)
from cfvs_maniskill.perception.images import DEPTH_RANGE, depth_normalise, normalise
from cfvs_maniskill.policies.cfvs.train import cli_main, resume_state
from cfvs_maniskill.policies.kovis.model import (
    KOVIS,
    KOVISConfig,
    implied_distance,
    kovis_loss,
    motion_targets,
)
from cfvs_maniskill.policies.networks import load_weights

FIELDS = ("images", "depth", "seg", "twist", "valid")


@dataclass
class TrainKOVISArgs:
    """Train KOVIS (keypoint encoder + depth/segmentation decoder + servo converter)."""

    data: tuple[Path, ...] = (Path("data/kovis.h5"),)
    """One or more `--kind kovis` dataset files (same peg)."""
    out: Path = Path("agents/kovis/round.pt")
    """Weights file to write (its resume state: OUT.resume)."""
    dof: int = 3
    """Motion dimensions the converter outputs: 3 (x y z), 4 (+ yaw) or 6."""
    keypoints: int = 8
    """Keypoints per image (KOVIS: 8 for its shaft, 10 for its plug)."""
    growth: tuple[int, int, int] = (12, 12, 64)
    """Dense growth rates of encoder, decoder, converter (KOVIS: 24 24 64; see README)."""
    epochs: int = 3
    batch: int = 64
    lr: float = 1e-3
    weight_decay: float = 5e-5
    augment: bool = True
    """KOVIS's image augmentation."""
    val_fraction: float = 0.05
    """The last rollouts of each file, held out for validation metrics."""
    max_minutes: float = 0.0
    """Stop after this many minutes (0: never) with the resume state saved."""
    checkpoint_minutes: float = 5.0
    """Save the resume state this often."""
    threads: int = 0
    """torch threads (0: all cores)."""
    seed: int = 0
    init: Path | None = None
    """Start from these KOVIS weights (continued training): encoder and decoder must have
    this run's keypoints and growth; the converter is taken too if its --dof matches. The
    keypoint Gaussian then stays at its final sigma."""


# ------------------------------------------------------------------------------ augmentation
def texture_bank(n: int, side: int, seed: int) -> torch.Tensor:
    """(n, side, side) fractal textures in [0, 1]: octaves of smoothly upsampled noise (the
    kind of image KOVIS pastes onto backgrounds and objects and adds as noise)."""
    g = torch.Generator().manual_seed(seed)
    out = torch.zeros(n, 1, side, side)
    for octave, cells in enumerate((4, 8, 16, 32)):
        noise = torch.rand(n, 1, cells, cells, generator=g)
        out += 0.6**octave * F.interpolate(noise, size=(side, side), mode="bicubic")
    out = out[:, 0]
    lo = out.flatten(1).min(1).values[:, None, None]
    hi = out.flatten(1).max(1).values[:, None, None]
    return (out - lo) / (hi - lo)


def augment(img: torch.Tensor, seg: torch.Tensor, bank: torch.Tensor, rng) -> torch.Tensor:
    """KOVIS's img_proc on grey levels (B, 2, S, S) float 0-255, each image drawn apart:
    half the backgrounds replaced by a texture, objects textured (0-40 levels), brightness
    x0.4-1.3, contrast x0.3-1.7, fractal noise of 8-40 levels. `seg`: classes (B, 2, s, s)."""
    b, v, s, _ = img.shape
    n = b * v
    x = img.reshape(n, s, s).clone()
    bg = F.interpolate((seg.reshape(n, 1, *seg.shape[-2:]) == 0).float(), size=(s, s))[:, 0]
    pick = lambda: bank[torch.from_numpy(rng.integers(len(bank), size=n))]  # noqa: E731
    u = lambda lo, hi: torch.from_numpy(rng.uniform(lo, hi, (n, 1, 1)).astype(np.float32))  # noqa: E731
    swap = torch.from_numpy(rng.uniform(size=(n, 1, 1)) < 0.5)
    backdrop = pick() * u(80, 255)
    x = torch.where(swap & (bg > 0.5), backdrop, x)
    x = x + (1 - bg) * (pick() - 0.5) * u(0, 40)
    mean = x.mean((1, 2), keepdim=True)
    x = ((x - mean) * u(0.3, 1.7) + mean) * u(0.4, 1.3)
    x = x + (pick() - 0.5) * 2 * u(8, 40)
    return x.clamp(0, 255).reshape(b, v, s, s)


# ------------------------------------------------------------------------------ schedules
def repeat_lr(progress: float) -> float:
    """KOVIS's 'repeat' schedule: cosine restarts on [0, .15, .3, .45, .6, .8, 1], each
    restart lower by where it starts; never below 1% of the base rate."""
    part = [0.0, 0.15, 0.30, 0.45, 0.6, 0.8, 1.0]
    i = min(int(np.digitize(progress, part)), len(part) - 1)
    period = part[i] - part[i - 1]
    a = 0.5 * (1 + math.cos(math.pi * (progress - part[i - 1]) / period)) * (1 - part[i - 1])
    return max(a, 0.01)


def sigma_at(progress: float, cfg: KOVISConfig) -> float:
    return min(2.0 * progress, 1.0) * (cfg.sigma[1] - cfg.sigma[0]) + cfg.sigma[0]


# ------------------------------------------------------------------------------ data
class Frames:
    """The valid frames of the loaded rollouts, as (rollout, frame) pairs."""

    def __init__(self, data: dict, rollouts: np.ndarray):
        valid = data["valid"][rollouts]
        r, k = np.nonzero(valid)
        self.pairs = np.stack([rollouts[r], k], axis=1)
        self.data = data

    def __len__(self) -> int:
        return len(self.pairs)

    def batch(self, idx: np.ndarray) -> dict[str, torch.Tensor]:
        r, k = self.pairs[idx, 0], self.pairs[idx, 1]
        d = self.data
        return {
            "images": torch.from_numpy(d["images"][r, k].astype(np.float32)),
            "depth": torch.from_numpy(d["depth"][r, k].astype(np.float32)),
            "seg": torch.from_numpy(d["seg"][r, k].astype(np.int64)),
            "twist": torch.from_numpy(d["twist"][r, k].astype(np.float32)),
        }


def forward(model: KOVIS, images: torch.Tensor, decode: bool = True) -> dict:
    x = normalise(images).contiguous(memory_format=torch.channels_last)
    return model(x[:, :1], x[:, 1:], decode=decode)


@torch.no_grad()
def validate(model: KOVIS, frames: Frames) -> dict[str, float]:
    """Direction error (deg) where the goal is over 1 cm away and within 2-10 mm; the
    distance the speed implies (-ln(1 - s) / a_dist) against the true one within 2 cm; the
    speed at the goal itself; depth error (mm) and segmentation accuracy of the decoder."""
    model.eval()
    cfg = model.cfg
    far, near, dist_err, at_goal, depth_err, seg_ok = [], [], [], [], [], []
    for a in range(0, len(frames), 128):
        b = frames.batch(np.arange(a, min(a + 128, len(frames))))
        out = forward(model, b["images"])
        want_dir, want_speed = motion_targets(b["twist"], cfg)
        d = -torch.log1p(-want_speed.clamp(max=1 - 1e-6)) / cfg.a_dist
        s = torch.sigmoid(out["speed"])
        ang = torch.rad2deg(
            torch.acos(F.cosine_similarity(out["direction"], want_dir, dim=-1).clamp(-1, 1))
        )
        far.append(ang[d > 0.01])
        near.append(ang[(d > 0.002) & (d <= 0.01)])
        d_hat = implied_distance(s, cfg)
        m = d < 0.02
        dist_err.append((d_hat[m] - d[m]).abs())
        at_goal.append(s[d < 1e-4])
        for i in range(2):
            dh, sh = out["decoded"][i]
            depth_err.append((dh - depth_normalise(b["depth"][:, i])).abs().mean((1, 2)))
            seg_ok.append((sh.argmax(1) == b["seg"][:, i]).float().mean((1, 2)))
    model.train()
    cat = lambda xs: torch.cat(xs).numpy() if xs else np.zeros(0)  # noqa: E731
    far, near, dist_err, at_goal = cat(far), cat(near), cat(dist_err), cat(at_goal)
    scale = 0.25 * (DEPTH_RANGE[1] - DEPTH_RANGE[0]) * 1000  # normalised units -> mm
    stat = lambda x, f: float(f(x)) if len(x) else float("nan")  # noqa: E731
    return {
        "direction_err_deg_mean": stat(far, np.mean),
        "direction_err_deg_p90": stat(far, lambda x: np.percentile(x, 90)),
        "direction_err_deg_near_mean": stat(near, np.mean),
        "distance_err_mm_mean": stat(dist_err, np.mean) * 1000,
        "speed_at_goal_mean": stat(at_goal, np.mean),
        "depth_err_mm_mean": float(cat(depth_err).mean()) * scale,
        "seg_accuracy": float(cat(seg_ok).mean()),
    }


# ------------------------------------------------------------------------------ training
def start_from(model: KOVIS, path: Path) -> dict:
    """Load `path`'s weights into `model` (see TrainKOVISArgs.init); its record."""
    init, blob = load_weights(path, "kovis")  # any peg: the encoder sees both
    have, want = init.cfg, model.cfg
    for field in ("keypoints", "image", "heatmap", "decode_full", "growth", "seg_classes"):
        if getattr(have, field) != getattr(want, field):
            raise WeightsError(
                f"{path}: field '{field}' is {getattr(have, field)}, this run builds "
                f"{getattr(want, field)} (--init needs the same encoder and decoder)"
            )
    parts = ["encoder", "decoder"]
    if have.motion_dims == want.motion_dims:
        parts.append("converter")
    else:
        print(f"--init: converter not taken ({have.motion_dims}-DoF, this run {want.motion_dims})")
    for name in parts:
        getattr(model, name).load_state_dict(getattr(init, name).state_dict())
    return {
        "path": str(path),
        "sha256": file_sha256(path),
        "parts": parts,
        "wall_time_s": blob.get("wall_time_s"),
    }


def train(args: TrainKOVISArgs) -> dict:
    if args.dof not in (3, 4, 6):
        raise DatasetError(f"--dof: expected 3, 4 or 6, got {args.dof}")
    if args.threads:
        torch.set_num_threads(args.threads)
    sets = load_sets(args.data, FIELDS, "kovis", "KOVIS", args.val_fraction)
    train_frames = Frames(sets.data, sets.train_idx)
    val_frames = Frames(sets.data, sets.val_idx)
    cfg = KOVISConfig(keypoints=args.keypoints, growth=args.growth, motion_dims=args.dof)
    torch.manual_seed(args.seed)
    model = KOVIS(cfg)
    started = start_from(model, args.init) if args.init else None
    model = model.to(memory_format=torch.channels_last)  # 25% faster convs on CPU
    opt = torch.optim.Adam(
        model.parameters(), lr=args.lr, weight_decay=args.weight_decay, amsgrad=True
    )
    bank = texture_bank(256, cfg.image, args.seed)
    steps = len(train_frames) // args.batch
    total = args.epochs * steps
    record = sets.record(file_sha256)
    sha = record["data_sha256"]
    free = ("max_minutes", "checkpoint_minutes", "threads")
    resume_path, run_key, blob = resume_state(args, sha, free)
    state = {"epoch": 0, "step": 0, "history": [], "wall_s": 0.0}
    if blob is not None:
        model.load_state_dict(blob["state_dict"])
        opt.load_state_dict(blob["optimizer"])
        state = blob["state"]
        print(f"resuming {args.out} at epoch {state['epoch'] + 1}, step {state['step']}")
    t_start = time.perf_counter() - state["wall_s"]
    t_session = t_saved = time.perf_counter()

    def save_resume() -> None:
        state["wall_s"] = time.perf_counter() - t_start
        blob = {"run_key": run_key, "data_sha256": sha, "state": state}
        blob.update(state_dict=model.state_dict(), optimizer=opt.state_dict())
        save_atomic(blob, resume_path)

    model.train()
    for epoch in range(state["epoch"], args.epochs):
        order = np.random.default_rng([args.seed, epoch]).permutation(len(train_frames))
        bar = tqdm(
            range(state["step"], steps),
            desc=f"kovis epoch {epoch + 1}/{args.epochs}",
            unit="batch",
            initial=state["step"],
            total=steps,
        )
        for s in bar:
            rng = np.random.default_rng([args.seed, epoch, s])
            progress = (epoch * steps + s) / total
            for group in opt.param_groups:
                group["lr"] = args.lr * repeat_lr(progress)
            model.sigma = cfg.sigma[1] if args.init else sigma_at(progress, cfg)
            b = train_frames.batch(order[s * args.batch : (s + 1) * args.batch])
            images = augment(b["images"], b["seg"], bank, rng) if args.augment else b["images"]
            out = forward(model, images)
            depth = tuple(depth_normalise(b["depth"][:, i]) for i in range(2))
            seg = (b["seg"][:, 0], b["seg"][:, 1])
            loss, parts = kovis_loss(out, depth, seg, b["twist"], cfg, boot=max(1 - progress, 0.3))
            opt.zero_grad()
            loss.backward()
            opt.step()
            state["step"] = s + 1
            if s % 10 == 0:
                bar.set_postfix(
                    loss=f"{loss.item():.3f}", **{k: f"{v:.3f}" for k, v in parts.items()}
                )
            now = time.perf_counter()
            if args.max_minutes and now - t_session > 60 * args.max_minutes:
                save_resume()
                print(f"stopped after {args.max_minutes} min; run the same command to resume")
                return state
            if now - t_saved > 60 * args.checkpoint_minutes:
                save_resume()
                t_saved = now
        bar.close()
        model.sigma = cfg.sigma[1]
        metrics = validate(model, val_frames)
        state["history"].append({"epoch": epoch + 1, **metrics})
        state["epoch"], state["step"] = epoch + 1, 0
        print(f"epoch {epoch + 1}: " + ", ".join(f"{k} {v:.3f}" for k, v in metrics.items()))
        save_resume()
    model.sigma = cfg.sigma[1]
    model = model.to(memory_format=torch.contiguous_format)
    meta = {
        "net": "kovis",
        "task": ",".join(str(p) for p in args.data),
        "peg": sets.peg,
        "config": dataclasses.asdict(cfg),
        "train_frames": len(train_frames),
        **record,
        "init": started,
    }
    wall = time.perf_counter() - t_start
    meta = write_weights(
        args.out, model, meta, "cfvs_maniskill.policies.kovis.train", args, state["history"], wall
    )
    resume_path.unlink(missing_ok=True)
    return meta


def main(argv: list[str] | None = None) -> int:
    return cli_main(TrainKOVISArgs, train, argv)


if __name__ == "__main__":
    sys.exit(main())
