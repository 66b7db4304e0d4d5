"""KOVIS (Puang, Tee, Jing, IROS 2020), the image-based visual-servoing baseline, after the
paper and its public code (enyen/KOVIS_VisualServo), written anew in plain torch.

- Encoder: a DenseNet U-Net (dense blocks 2-3-4 down, 4-3-2 up, skip connections) on one
  grey 96 x 96 image -> K heatmaps at 48 x 48 -> keypoints: a spatial soft-argmax centre
  (x, y in [-1, 1]) and a presence mu = sigmoid(the heatmap's largest logit). The same
  encoder sees the left and the right imager of the stereo pair.
- Decoder (self-supervision): K Gaussian maps drawn at the keypoints (scaled by mu) -> the
  image's depth and its segmentation (background / peg / hole object) at 96 x 96, through
  a transposed DenseNet (blocks 4-3, with coordinate channels). Only the keypoints pass
  this bottleneck, so they must mark the scene's geometry.
- Converter: a dense fully connected net (blocks 4-4-4) from both images' keypoints
  (2 x 3K numbers) -> a motion direction in the tool frame (the task's degrees of freedom)
  and a speed logit; the target speed is 1 - exp(-a_dist * distance to the goal).

Losses (`kovis_loss`, as the original's training script): depth smooth-L1 and segmentation
cross-entropy on both images, direction 1 - cos weighted by the target speed, speed BCE
(all four "bootstrapped": the hardest fraction of pixels / samples, annealed from all to
30%; the speed's hardest by BCE minus the soft target's entropy, see kovis_loss),
keypoint concentration exp(-20 d) * mu_i * mu_j between every pair, and an "inside" term
that keeps heatmap mass off the background.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn


@dataclass
class KOVISConfig:
    keypoints: int = 8
    """K per image (KOVIS's shaft insertion: 8; its plug: 10)."""
    image: int = 96
    """Input side, pixels (KOVIS's im_size)."""
    heatmap: int = 48
    """Heatmap side (the encoder's U-Net ends one level above the input)."""
    decode_full: bool = False
    """True: the decoder draws depth and segmentation at the image's side, as KOVIS does;
    False: at the heatmap's side (targets halved), 4x cheaper on a CPU."""
    growth: tuple[int, int, int] = (24, 24, 64)
    """Dense growth rates of encoder, decoder and converter (KOVIS's: 24, 24, 64)."""
    blocks_down: tuple[int, int, int] = (2, 3, 4)
    blocks_up: tuple[int, int, int] = (4, 3, 2)
    blocks_decoder: tuple[int, int] = (4, 3)
    blocks_converter: tuple[int, int, int] = (4, 4, 4)
    sigma: tuple[float, float] = (1.0, 2.5)
    """Keypoint Gaussian sharpness exp(-sigma d^2) (d in heatmap cells), annealed from the
    first to the second over the first half of training (KOVIS's sigma_kp)."""
    seg_classes: int = 3
    """Background, peg, hole object."""
    motion_dims: int = 3
    """3 (x y z), 4 (+ yaw) or 6 (+ tilt): the task's degrees of freedom."""
    rot_mul: float = 5.0
    """A unit motion turns rot_mul rad per metre travelled (KOVIS's rot_mul)."""
    a_dist: float = 200.0
    """Target speed = 1 - exp(-a_dist * distance), distance in metres (KOVIS's a_dist)."""


def _act() -> nn.Module:
    return nn.SiLU()


class DenseLayer(nn.Module):
    """BN-SiLU dense layer: [1x1 bottleneck when wide] + 3x3 (dilated) conv; appends its
    `growth` channels to its input."""

    def __init__(self, cin: int, growth: int, dilation: int = 1, coords: bool = False):
        super().__init__()
        self.coords = coords
        cin += 2 if coords else 0
        layers: list[nn.Module] = []
        if cin >= 5 * growth:
            layers += [nn.Conv2d(cin, 4 * growth, 1, bias=False), nn.BatchNorm2d(4 * growth)]
            layers += [_act()]
            cin = 4 * growth
        layers += [nn.Conv2d(cin, growth, 3, padding=dilation, dilation=dilation, bias=False)]
        layers += [nn.BatchNorm2d(growth), _act()]
        self.f = nn.Sequential(*layers)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.coords:  # CoordConv: where a pixel is, for a decoder drawing from blobs
            n, _, h, w = x.shape
            yy = torch.linspace(-1, 1, h, device=x.device).view(1, 1, h, 1).expand(n, 1, h, w)
            xx = torch.linspace(-1, 1, w, device=x.device).view(1, 1, 1, w).expand(n, 1, h, w)
            x = torch.cat([yy, xx, x], dim=1)
        return torch.cat([x, self.f(x)], dim=1)


def dense_block(n: int, cin: int, growth: int, dilate: bool = False, coords: bool = False):
    """-> (block, output channels). Dilation grows by one per layer when `dilate`."""
    layers = []
    for i in range(n):
        c = coords and i == 0
        layers.append(DenseLayer(cin, growth, i + 1 if dilate else 1, c))
        cin += growth + (2 if c else 0)
    return nn.Sequential(*layers), cin


def down(cin: int, cout: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(cin, cout, 1, bias=False), nn.AvgPool2d(2),
                         nn.BatchNorm2d(cout), _act())  # fmt: skip


def up(cin: int, cout: int) -> nn.Sequential:
    return nn.Sequential(nn.ConvTranspose2d(cin, cout, 2, 2, bias=False),
                         nn.BatchNorm2d(cout), _act())  # fmt: skip


class Encoder(nn.Module):
    """Grey image -> K heatmap logits at half the image's side (a dense U-Net)."""

    def __init__(self, cfg: KOVISConfig):
        super().__init__()
        g = cfg.growth[0]
        (a, b, c), (d, e, f) = cfg.blocks_down, cfg.blocks_up
        b1, n = dense_block(a, 1, g)
        self.down1 = nn.Sequential(b1, down(n, n // 2))
        c1 = n // 2
        b2, n = dense_block(b, c1, g)
        self.down2 = nn.Sequential(b2, down(n, n // 2))
        c2 = n // 2
        b3, n = dense_block(c, c2, g, dilate=True)
        self.down3 = nn.Sequential(b3, down(n, n // 2))
        b4, n = dense_block(d, n // 2, g, dilate=True)
        self.up1 = nn.Sequential(b4, up(n, n // 2))
        b5, n = dense_block(e, n // 2 + c2, g, dilate=True)
        self.up2 = nn.Sequential(b5, up(n, n // 2))
        self.up3, n = dense_block(f, n // 2 + c1, g, dilate=True)
        self.head = nn.Conv2d(n, cfg.keypoints, 3, padding=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        d1 = self.down1(x)
        d2 = self.down2(d1)
        u1 = self.up1(self.down3(d2))
        u2 = self.up2(torch.cat([u1, d2], dim=1))
        return self.head(self.up3(torch.cat([u2, d1], dim=1)))


class Decoder(nn.Module):
    """K keypoint Gaussian maps -> depth (1 channel) and segmentation logits at the image's
    side or the heatmap's (`decode_full`; a transposed dense net with coordinate channels)."""

    def __init__(self, cfg: KOVISConfig):
        super().__init__()
        g = cfg.growth[1]
        b1, n = dense_block(cfg.blocks_decoder[0], cfg.keypoints, g, coords=True)
        if cfg.decode_full:
            self.b1 = nn.Sequential(b1, up(n, n // 2))
        else:  # the same transition without the upsampling
            self.b1 = nn.Sequential(b1, nn.Conv2d(n, n // 2, 1, bias=False),
                                    nn.BatchNorm2d(n // 2), _act())  # fmt: skip
        self.b2, n = dense_block(cfg.blocks_decoder[1], n // 2, g, dilate=True, coords=True)
        self.depth = nn.Conv2d(n, 1, 3, padding=1)
        self.seg = nn.Conv2d(n, cfg.seg_classes, 3, padding=1)

    def forward(self, maps: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        x = self.b2(self.b1(maps))
        return self.depth(x)[:, 0], self.seg(x)


class Converter(nn.Module):
    """Keypoints of both images (B, 6K) -> (direction (B, D) unit, speed logit (B,))."""

    def __init__(self, cfg: KOVISConfig):
        super().__init__()
        g, n = cfg.growth[2], 6 * cfg.keypoints
        layers: list[nn.Module] = []
        for i, count in enumerate(cfg.blocks_converter):
            for _ in range(count):
                layers.append(_DenseFC(n, g))
                n += g
            if i < len(cfg.blocks_converter) - 1:
                layers += [nn.Linear(n, n // 2, bias=False), nn.BatchNorm1d(n // 2), _act()]
                n //= 2
        self.body = nn.Sequential(*layers)
        self.direction = nn.Linear(n, cfg.motion_dims)
        self.speed = nn.Linear(n, 1)

    def forward(self, kp: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        x = self.body(kp)
        return F.normalize(self.direction(x), dim=-1), self.speed(x)[:, 0]


class _DenseFC(nn.Module):
    def __init__(self, cin: int, growth: int):
        super().__init__()
        self.f = nn.Sequential(nn.Linear(cin, growth, bias=False), nn.BatchNorm1d(growth), _act())

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.cat([x, self.f(x)], dim=1)


class KOVIS(nn.Module):
    def __init__(self, cfg: KOVISConfig):
        super().__init__()
        self.cfg = cfg
        self.encoder = Encoder(cfg)
        self.decoder = Decoder(cfg)
        self.converter = Converter(cfg)
        self.sigma = cfg.sigma[1]
        """The Gaussian sharpness in use (training anneals it; inference: the final one)."""
        g = torch.arange(cfg.heatmap, dtype=torch.float32)
        self.register_buffer("grid", g, persistent=False)

    def keypoints(self, image: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(B, 1, S, S) normalised -> keypoints (B, K, 3): x, y in [-1, 1] and presence mu,
        and their Gaussian maps (B, K, S/2, S/2) scaled by mu."""
        logits = self.encoder(image)
        b, k, h, w = logits.shape
        flat = logits.flatten(2)
        p = flat.softmax(-1).view(b, k, h, w)
        cy = (p.sum(3) * self.grid[:h]).sum(-1)  # heatmap cells
        cx = (p.sum(2) * self.grid[:w]).sum(-1)
        mu = flat.max(-1).values.sigmoid()
        gy = torch.exp(-self.sigma * (self.grid[:h].view(1, 1, h, 1) - cy[..., None, None]) ** 2)
        gx = torch.exp(-self.sigma * (self.grid[:w].view(1, 1, 1, w) - cx[..., None, None]) ** 2)
        maps = gy * gx * mu[..., None, None]
        kp = torch.stack([cx * 2 / w - 1, cy * 2 / h - 1, mu], dim=-1)
        return kp, maps

    def forward(self, left: torch.Tensor, right: torch.Tensor, decode: bool = True):
        """Both images (B, 1, S, S), normalised -> dict of keypoints (B, K, 3) and maps of
        each image, direction (B, D), speed logit (B,), and (when `decode`) each image's
        depth (B, S, S) and segmentation logits (B, C, S, S)."""
        kl, ml = self.keypoints(left)
        kr, mr = self.keypoints(right)
        direction, speed = self.converter(torch.cat([kl.flatten(1), kr.flatten(1)], dim=1))
        out = {"kp": (kl, kr), "maps": (ml, mr), "direction": direction, "speed": speed}
        if decode:
            out["decoded"] = (self.decoder(ml), self.decoder(mr))
        return out


MOTION_DIMS = {3: [0, 1, 2], 4: [0, 1, 2, 5], 6: [0, 1, 2, 3, 4, 5]}
"""Which of (dx, dy, dz, rx, ry, rz) a converter with that many outputs drives."""


def motion_targets(twist: torch.Tensor, cfg: KOVISConfig) -> tuple[torch.Tensor, torch.Tensor]:
    """Tool-frame body twist to the goal (B, 6): (v, w) with the goal = pose * exp(twist)
    -> unit direction (B, D) and target speed (B,) in [0, 1). Rotation enters the direction
    as w / rot_mul (a unit motion turns rot_mul rad per metre), as KOVIS's rollouts do."""
    m = twist[:, MOTION_DIMS[cfg.motion_dims]].clone()
    m[:, 3:] /= cfg.rot_mul
    dist = m.norm(dim=-1)
    return F.normalize(m, dim=-1), 1 - torch.exp(-cfg.a_dist * dist)


def implied_distance(speed, cfg: KOVISConfig):
    """The distance to the goal a speed implies: motion_targets' 1 - exp(-a_dist d) inverted,
    the speed capped at 0.9999 (about 46 mm at a_dist 200). `speed`: a float or a tensor."""
    if isinstance(speed, torch.Tensor):
        return -torch.log1p(-speed.clamp(max=0.9999)) / cfg.a_dist
    return -np.log1p(-min(speed, 0.9999)) / cfg.a_dist


def _hardest(x: torch.Tensor, fraction: float, key: torch.Tensor | None = None) -> torch.Tensor:
    """Mean of x over the largest `fraction` of `key` (default x) along the last axis
    (KOVIS's bootstrapping)."""
    k = max(1, int(round(fraction * x.shape[-1])))
    if key is None:
        return x.topk(k, dim=-1, sorted=False).values.mean()
    return x.gather(-1, key.topk(k, dim=-1, sorted=False).indices).mean()


def _entropy(p: torch.Tensor) -> torch.Tensor:
    """Binary entropy (nats): the lowest BCE a soft target p allows."""
    p = p.clamp(1e-6, 1 - 1e-6)
    return -(p * p.log() + (1 - p) * (1 - p).log())


def kovis_loss(
    out: dict,
    depth: tuple[torch.Tensor, torch.Tensor],
    seg: tuple[torch.Tensor, torch.Tensor],
    twist: torch.Tensor,
    cfg: KOVISConfig,
    boot: float = 1.0,
    concentrate: float = 20.0,
    inside: float = 100.0,
) -> tuple[torch.Tensor, dict[str, float]]:
    """KOVIS's training loss. depth: each image's target (B, S, S), normalised like the
    decoder's output; seg: class ids (B, S, S) int64; twist: (B, 6) to the goal; boot: the
    bootstrapped fraction (1 early in training, down to 0.3)."""
    want_dir, want_speed = motion_targets(twist, cfg)
    l_depth = l_seg = l_conc = l_in = 0.0
    for i in range(2):
        d_hat, s_hat = out["decoded"][i]
        l_depth = l_depth + _hardest(
            F.smooth_l1_loss(d_hat, depth[i], reduction="none").view(1, -1), boot
        )
        l_seg = l_seg + _hardest(F.cross_entropy(s_hat, seg[i], reduction="none").view(1, -1), boot)
        kp = out["kp"][i]
        dist = torch.cdist(kp[..., :2], kp[..., :2])
        mu = kp[..., 2]
        pair = torch.triu(torch.ones(cfg.keypoints, cfg.keypoints), diagonal=1)
        weight = mu[:, :, None] * mu[:, None, :] * pair
        l_conc = l_conc + (torch.exp(-concentrate * dist) * weight).sum((1, 2)).mean() / pair.sum()
        maps = out["maps"][i]
        bg = (seg[i] == 0).float()[:, None]
        bg = F.interpolate(bg, size=maps.shape[-2:], mode="bilinear", align_corners=False)
        l_in = l_in + inside * (bg * maps).mean()
    l_dir = _hardest(
        ((1 - F.cosine_similarity(out["direction"], want_dir, dim=-1)) * want_speed)[None], boot
    )
    # Bootstrapped by what is left to learn (BCE - entropy = KL), not by BCE as KOVIS does:
    # with soft targets the highest BCE belongs to targets near 0.5, whose BCE cannot fall
    # below their entropy, so KOVIS's rule fed the speed head samples with no gradient left
    # (measured: a speed head constant to 0.05; agents/kovis/README.md).
    bce = F.binary_cross_entropy_with_logits(out["speed"], want_speed, reduction="none")
    l_speed = _hardest(bce[None], boot, key=(bce - _entropy(want_speed)).detach()[None])
    loss = (l_depth + l_seg + l_conc + l_in) / 2 + l_dir + l_speed
    halves = {"depth": l_depth, "seg": l_seg, "conc": l_conc, "inside": l_in}
    parts = {k: float(v.detach()) / 2 for k, v in halves.items()}
    parts.update(dir=float(l_dir.detach()), speed=float(l_speed.detach()))
    return loss, parts
