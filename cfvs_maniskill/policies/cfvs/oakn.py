"""OAKN, the object-agnostic keypoint network (paper, section OAKN).

Per point x_i: offsets to the three keypoints (k_ij = x_i + dk_ij) and a confidence w_i
(sigmoid). Keypoints are the confidence-weighted means of the candidates (paper, Eq. for
k_j); the hole pose follows from them by Algorithm 1 (`data.labels.hole_frame_from_keypoints`).

Input: the tool-frame object cloud (B, N, 3), metres. The cloud is centred on its mean and
scaled by `SCALE` before the backbone: offsets are translation-equivariant, so centring
lets the same hole seen at 15 or 30 cm look the same to the network.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor, nn

from cfvs_maniskill.nets.pointnet2 import EncoderConfig, FeaturePropagation, encoder, mlp

SCALE = 10.0
"""Network units are decimetres: coordinates x10, offsets predicted /10."""


@dataclass(frozen=True)
class OAKNConfig(EncoderConfig):
    sa1_radii: tuple[float, ...] = (0.03,)
    """One radius: MSG (2 radii) doubled the CPU step time for this cloud size (416 -> 726
    ms at B=16) and so halved the epochs that fit in a session."""
    sa2_radius: float = 0.08


class OAKN(nn.Module):
    def __init__(self, cfg: OAKNConfig = OAKNConfig()):
        super().__init__()
        self.cfg = cfg
        w = cfg.width
        self.sa1, self.sa2, self.glob = encoder(cfg, SCALE)
        self.fp3 = FeaturePropagation(self.glob.out_ch, self.sa2.out_ch, [2 * w])
        self.fp2 = FeaturePropagation(2 * w, self.sa1.out_ch, [2 * w])
        self.fp1 = FeaturePropagation(2 * w, 3, [2 * w, 2 * w])
        self.head = nn.Sequential(mlp([2 * w, w]), nn.Linear(w, 10))

    def forward(self, points: Tensor) -> tuple[Tensor, Tensor]:
        """points (B, N, 3) metres -> offsets (B, N, 3, 3) metres, confidence logits (B, N)."""
        x = (points - points.mean(dim=1, keepdim=True)) * SCALE
        c1, f1 = self.sa1(x, None)
        c2, f2 = self.sa2(c1, f1)
        g = self.glob(c2, f2).unsqueeze(1)  # (B, 1, C)
        f = self.fp3(c2, g[:, :, :0].new_zeros(g.shape[0], 1, 3), g, f2)
        f = self.fp2(c1, c2, f, f1)
        f = self.fp1(x, c1, f, x)
        out = self.head(f)
        return out[..., :9].reshape(*out.shape[:2], 3, 3) / SCALE, out[..., 9]


def weighted_keypoints(
    points: Tensor, offsets: Tensor, weights: Tensor | None
) -> tuple[Tensor, Tensor]:
    """Candidates x_i + dk_ij averaged with weights w_i (uniform if None: the paper's
    "without confidence map" ablation). Returns keypoints (B, 3, 3) and candidates."""
    cand = points.unsqueeze(2) + offsets  # (B, N, 3, 3)
    if weights is None:
        return cand.mean(dim=1), cand
    w = weights / weights.sum(dim=1, keepdim=True).clamp_min(1e-9)
    return (cand * w[:, :, None, None]).sum(dim=1), cand


def keypoint_spread(cand: Tensor, keypoints: Tensor, weights: Tensor | None) -> Tensor:
    """(B,) how far the first keypoint's candidates (the opening's centre) lie from it, RMS,
    weighted as the keypoint was: OAKN's own uncertainty about the opening."""
    d2 = ((cand[:, :, 0] - keypoints[:, None, 0]) ** 2).sum(dim=-1)  # (B, N)
    if weights is None:
        return d2.mean(dim=1).sqrt()
    w = weights / weights.sum(dim=1, keepdim=True).clamp_min(1e-9)
    return (w * d2).sum(dim=1).sqrt()


def oakn_loss(
    offsets: Tensor, logits: Tensor, offsets_gt: Tensor, conf_gt: Tensor
) -> tuple[Tensor, dict[str, float]]:
    """Paper: L = L_kpts + L_map. L_kpts = 1/N sum_i sum_j w*_i |dk_ij - dk*_ij|_1 (here
    in network units, decimetres, so both terms are O(1)); L_map = RMSE(w, w*)."""
    l1 = (offsets - offsets_gt).abs().sum(dim=-1).sum(dim=-1) * SCALE  # (B, N)
    l_kpts = (conf_gt * l1).mean()
    l_map = torch.sqrt(((torch.sigmoid(logits) - conf_gt) ** 2).mean() + 1e-12)
    return l_kpts + l_map, {"l_kpts": l_kpts.item(), "l_map": l_map.item()}
