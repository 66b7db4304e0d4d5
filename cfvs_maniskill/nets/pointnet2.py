"""PointNet++ (Qi et al. 2017) in pure torch, for CPU: no CUDA extensions.

Tensors are channel-last throughout -- points (B, N, 3), features (B, N, C) -- so every
shared MLP is an `nn.Linear` over the last axis, which on CPU is faster than the usual
Conv2d(1x1) + BatchNorm (measured on a 2-core CPU). LayerNorm replaces
BatchNorm so batch size 1 at inference behaves exactly like training.

Farthest point sampling uses `fpsample` (Rust, QuickFPS): a python loop costs 10x more and
is the bottleneck at batch size 1. Sampling indices carry no gradient, as in the original.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import fpsample
import numpy as np
import torch
from torch import Tensor, nn

_rng = np.random.default_rng(0)


def seed_sampling(seed: int) -> None:
    """Seed the random FPS start points used in training mode."""
    global _rng
    _rng = np.random.default_rng(seed)


def farthest_point_sample(xyz: Tensor, m: int, random_start: bool = False) -> Tensor:
    """(B, N, 3) -> (B, m) indices of m mutually far points per cloud.

    Deterministic (starts from point 0) unless `random_start` (training)."""
    pts = xyz.detach().cpu().numpy()
    b, n, _ = pts.shape
    if m >= n:
        return torch.arange(n).expand(b, n).clone()
    out = np.empty((b, m), dtype=np.int64)
    for i in range(b):
        start = int(_rng.integers(n)) if random_start else 0
        out[i] = fpsample.bucket_fps_kdline_sampling(pts[i], m, h=5, start_idx=start)
    return torch.from_numpy(out).to(xyz.device)


def gather(x: Tensor, idx: Tensor) -> Tensor:
    """x (B, N, C), idx (B, ...) -> (B, ..., C). One index_select of whole rows: on CPU
    torch.gather with an expanded index costs 8x more for 64 channels."""
    b, n, c = x.shape
    flat = (idx.reshape(b, -1) + torch.arange(b, device=x.device)[:, None] * n).reshape(-1)
    return x.reshape(b * n, c).index_select(0, flat).reshape(*idx.shape, c)


def ball_query(xyz: Tensor, centres: Tensor, radius: float, k: int) -> Tensor:
    """Indices (B, M, k) of up to k points of xyz (B, N, 3) within `radius` of each centre
    (B, M, 3), nearest first; short neighbourhoods repeat their nearest point (the centre
    itself is always a member, so every ball has one)."""
    d2 = torch.cdist(centres, xyz).square()  # (B, M, N)
    k = min(k, xyz.shape[1])
    dist, idx = torch.topk(d2, k, dim=-1, largest=False)
    outside = dist > radius * radius
    return torch.where(outside, idx[..., :1].expand_as(idx), idx)


def mlp(dims: Sequence[int], last_act: bool = True) -> nn.Sequential:
    """Shared MLP over the last axis: Linear -> LayerNorm -> ReLU per layer."""
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(zip(dims[:-1], dims[1:], strict=True)):
        layers.append(nn.Linear(a, b))
        if i < len(dims) - 2 or last_act:
            layers += [nn.LayerNorm(b), nn.ReLU(inplace=True)]
    return nn.Sequential(*layers)


class SetAbstraction(nn.Module):
    """Sample `m` centres (FPS), group neighbours in one or more balls (MSG when several
    radii are given), run a shared MLP on [relative xyz / radius, features], max-pool."""

    def __init__(
        self,
        m: int,
        radii: Sequence[float],
        ks: Sequence[int],
        in_ch: int,
        mlps: Sequence[Sequence[int]],
    ):
        super().__init__()
        assert len(radii) == len(ks) == len(mlps), "one k and one MLP per radius"
        self.m, self.radii, self.ks = m, list(radii), list(ks)
        self.mlps = nn.ModuleList([mlp([in_ch + 3, *dims]) for dims in mlps])
        self.out_ch = sum(dims[-1] for dims in mlps)

    def forward(self, xyz: Tensor, feats: Tensor | None) -> tuple[Tensor, Tensor]:
        """xyz (B, N, 3), feats (B, N, C) or None -> centres (B, m, 3), feats (B, m, out_ch)."""
        idx = farthest_point_sample(xyz, self.m, random_start=self.training)
        centres = gather(xyz, idx)
        outs = []
        for radius, k, net in zip(self.radii, self.ks, self.mlps, strict=True):
            nb = ball_query(xyz, centres, radius, k)
            rel = (gather(xyz, nb) - centres.unsqueeze(2)) / radius  # (B, m, k, 3)
            x = rel if feats is None else torch.cat([rel, gather(feats, nb)], dim=-1)
            outs.append(net(x).amax(dim=2))  # amax: no argmax kept, 25x cheaper than max
        return centres, torch.cat(outs, dim=-1)


class GlobalAbstraction(nn.Module):
    """All points in one group: shared MLP on [xyz, features], max over points."""

    def __init__(self, in_ch: int, dims: Sequence[int]):
        super().__init__()
        self.net = mlp([in_ch + 3, *dims])
        self.out_ch = dims[-1]

    def forward(self, xyz: Tensor, feats: Tensor) -> Tensor:
        return self.net(torch.cat([xyz, feats], dim=-1)).amax(dim=1)  # (B, C)


class FeaturePropagation(nn.Module):
    """Carry features from sparse points back to dense ones: inverse-distance weighted
    mean of the 3 nearest sparse points, concatenated with the dense skip features, MLP."""

    def __init__(self, in_ch: int, skip_ch: int, dims: Sequence[int]):
        super().__init__()
        self.net = mlp([in_ch + skip_ch, *dims])
        self.out_ch = dims[-1]

    def forward(self, dense_xyz: Tensor, sparse_xyz: Tensor, sparse: Tensor, skip: Tensor | None):
        if sparse_xyz.shape[1] == 1:
            up = sparse.expand(-1, dense_xyz.shape[1], -1)
        else:
            d = torch.cdist(dense_xyz, sparse_xyz)  # (B, N, S)
            dist, idx = torch.topk(d, min(3, d.shape[-1]), dim=-1, largest=False)
            w = 1.0 / (dist + 1e-8)
            w = w / w.sum(dim=-1, keepdim=True)
            up = (gather(sparse, idx) * w.unsqueeze(-1)).sum(dim=2)
        x = up if skip is None else torch.cat([up, skip], dim=-1)
        return self.net(x)


@dataclass(frozen=True)
class EncoderConfig:
    """Two set abstractions and a global one: the encoder both CFVS networks share."""

    sa1_centres: int = 256
    sa1_radii: tuple[float, ...] = (0.03,)
    """Ball radii of the first set abstraction, metres (several = MSG)."""
    sa1_k: tuple[int, ...] = (16,)
    sa2_centres: int = 64
    sa2_radius: float = 0.08
    sa2_k: int = 16
    width: int = 64
    """Base channel width; layers use 1-4x this."""


def encoder(
    cfg: EncoderConfig, scale: float
) -> tuple[SetAbstraction, SetAbstraction, GlobalAbstraction]:
    """SA1 -> SA2 -> global, for inputs multiplied by `scale` (radii are given in metres)."""
    w = cfg.width
    sa1 = SetAbstraction(
        cfg.sa1_centres,
        [r * scale for r in cfg.sa1_radii],
        cfg.sa1_k,
        0,
        [[w // 2, w // 2, w]] * len(cfg.sa1_radii),
    )
    sa2 = SetAbstraction(
        cfg.sa2_centres, [cfg.sa2_radius * scale], [cfg.sa2_k], sa1.out_ch, [[w, w, 2 * w]]
    )
    return sa1, sa2, GlobalAbstraction(sa2.out_ch, [2 * w, 4 * w])
