"""KOVIS (Puang et al. 2020), the image-based visual-servoing baseline, in small CPU form.

- Keypoint encoder: grayscale wrist image -> K heatmaps -> spatial soft-argmax keypoints
  (x, y) with a presence mu (the heatmap's peak probability, rescaled).
- Depth decoder (self-supervision): K Gaussian maps drawn at the keypoints -> the depth
  image (at half the input's side). Only the keypoints pass this bottleneck, so they must mark the scene's geometry.
- Servo converter: keypoints -> a unit motion direction in the tool frame and a speed in
  (0, 1) (a logit, trained with binary cross-entropy as KOVIS does).
Encoder, decoder and converter train jointly (KOVIS's losses: depth smooth-L1, direction
1 - cos weighted by the target speed, speed BCE, and a concentration term keeping
keypoints apart).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn


@dataclass
class KOVISConfig:
    keypoints: int = 8
    """K (KOVIS's default is 8)."""
    channels: int = 16
    image: int = 64
    """Input side, pixels."""
    heatmap: int = 16
    """Heatmap side (the encoder halves the image twice)."""
    sigma: float = 1.5
    """Gaussian width of a keypoint on the heatmap grid, cells."""
    motion_dims: int = 6
    """3 (x y z), 4 (+ yaw) or 6 (+ tilt): the task's degrees of freedom."""
    rot_scale: float = 0.1
    """Metres per radian when rotation and translation share one direction vector."""
    speed_range: float = 0.1
    """Distance (metres, rotation scaled) at which the target speed saturates at 1."""


def _conv(cin: int, cout: int, stride: int = 1) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(cin, cout, 3, stride, 1), nn.GroupNorm(8, cout), nn.ReLU())


class KOVIS(nn.Module):
    def __init__(self, cfg: KOVISConfig):
        super().__init__()
        self.cfg = cfg
        c, k = cfg.channels, cfg.keypoints
        self.encoder = nn.Sequential(
            _conv(1, c), _conv(c, 2 * c, 2), _conv(2 * c, 2 * c), _conv(2 * c, 2 * c, 2),
            _conv(2 * c, 2 * c), nn.Conv2d(2 * c, k, 1),
        )  # fmt: skip
        self.decoder = nn.Sequential(
            _conv(k, 2 * c), _conv(2 * c, 2 * c), nn.Upsample(scale_factor=2),
            _conv(2 * c, c), nn.Conv2d(c, 1, 3, 1, 1),
        )  # fmt: skip
        self.converter = nn.Sequential(
            nn.Linear(3 * k, 256), nn.LayerNorm(256), nn.ReLU(),
            nn.Linear(256, 256), nn.LayerNorm(256), nn.ReLU(),
            nn.Linear(256, cfg.motion_dims + 1),
        )  # fmt: skip
        g = torch.linspace(-1, 1, cfg.heatmap)
        self.register_buffer("grid", g, persistent=False)

    @staticmethod
    def normalise(gray: torch.Tensor) -> torch.Tensor:
        """(B, S, S) uint8 -> (B, 1, S, S), zero mean, unit std per image (the wrist image's
        brightness varies with the scene, its structure is what matters)."""
        x = gray.float()[:, None]
        mean = x.mean(dim=(2, 3), keepdim=True)
        std = x.std(dim=(2, 3), keepdim=True).clamp_min(1.0)
        return (x - mean) / std

    def keypoints(self, gray: torch.Tensor) -> torch.Tensor:
        """(B, S, S) uint8 -> (B, K, 3): x, y in [-1, 1] and presence mu in [0, 1]."""
        logits = self.encoder(self.normalise(gray))
        b, k, h, w = logits.shape
        p = logits.flatten(2).softmax(-1).view(b, k, h, w)
        x = (p.sum(2) * self.grid).sum(-1)
        y = (p.sum(3) * self.grid).sum(-1)
        mu = (p.flatten(2).max(-1).values * h * w / 16).clamp(max=1.0)
        return torch.stack([x, y, mu], dim=-1)

    def gaussian_maps(self, kp: torch.Tensor) -> torch.Tensor:
        s = 2 * self.cfg.sigma / self.cfg.heatmap
        dx = (self.grid[None, None, None, :] - kp[..., 0, None, None]) ** 2
        dy = (self.grid[None, None, :, None] - kp[..., 1, None, None]) ** 2
        return kp[..., 2, None, None] * torch.exp(-(dx + dy) / (2 * s**2))

    def forward(self, gray: torch.Tensor):
        """-> keypoints (B, K, 3), depth (B, 1, S/2, S/2), direction (B, D), speed logit (B,)."""
        kp = self.keypoints(gray)
        depth = self.decoder(self.gaussian_maps(kp))
        out = self.converter(kp.flatten(1))
        return kp, depth, F.normalize(out[:, :-1], dim=-1), out[:, -1]


def motion_targets(action: torch.Tensor, cfg: KOVISConfig) -> tuple[torch.Tensor, torch.Tensor]:
    """Tool-frame (dt, dr) (B, 6) -> unit direction (B, D) and target speed (B,) in [0, 1]."""
    dims = {3: [0, 1, 2], 4: [0, 1, 2, 5], 6: [0, 1, 2, 3, 4, 5]}[cfg.motion_dims]
    m = action[:, dims].clone()
    m[:, 3:] *= cfg.rot_scale
    dist = m.norm(dim=-1)
    return F.normalize(m, dim=-1), (dist / cfg.speed_range).clamp(max=1.0)


def kovis_loss(out, depth_target: torch.Tensor, action: torch.Tensor, cfg: KOVISConfig):
    kp, depth, direction, speed_logit = out
    want_dir, want_speed = motion_targets(action, cfg)
    l_depth = F.smooth_l1_loss(depth[:, 0], depth_target, beta=0.02) * 10
    l_dir = ((1 - F.cosine_similarity(direction, want_dir, dim=-1)) * want_speed).mean()
    l_speed = F.binary_cross_entropy_with_logits(speed_logit, want_speed)
    d = torch.cdist(kp[..., :2], kp[..., :2])
    off_diag = 1 - torch.eye(kp.shape[1])
    l_conc = (torch.exp(-20 * d) * off_diag).sum((1, 2)).mean() / off_diag.sum()
    loss = l_depth + l_dir + l_speed + 0.1 * l_conc
    parts = {
        k: float(v.detach()) for k, v in (("depth", l_depth), ("dir", l_dir), ("speed", l_speed))
    }
    return loss, parts
