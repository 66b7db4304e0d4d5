"""OPN, the offsets prediction network (paper, section OPN).

The cloud cropped around the end-effector (tool frame, not centred: the tool's origin is
the reference the offsets are measured from) -> PointNet++ global feature -> MLP ->
dt (3, metres) and dr (3, rotation vector, radians), the tool-frame offset to the
pre-insertion pose (`data.labels.fine_action`).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from cfvs_maniskill.nets.pointnet2 import EncoderConfig, encoder, mlp

POINT_SCALE = 10.0
"""Coordinates enter in decimetres."""
DT_UNIT = 0.01
"""dt is predicted in centimetres ..."""
DR_UNIT = 0.1
"""... and dr in tenths of a radian (5.7 deg), so both are O(1)."""


@dataclass(frozen=True)
class OPNConfig(EncoderConfig):
    sa1_radii: tuple[float, ...] = (0.015,)
    """The fine crop is 16 cm across: smaller balls than OAKN's."""
    sa2_radius: float = 0.04


class OPN(nn.Module):
    def __init__(self, cfg: OPNConfig = OPNConfig()):
        super().__init__()
        self.cfg = cfg
        w = cfg.width
        self.sa1, self.sa2, self.glob = encoder(cfg, POINT_SCALE)
        self.head = nn.Sequential(mlp([4 * w, 2 * w, w]), nn.Linear(w, 6))

    def forward(self, points: Tensor) -> Tensor:
        """points (B, N, 3) metres, tool frame -> (B, 6): dt metres, dr radians."""
        x = points * POINT_SCALE
        c1, f1 = self.sa1(x, None)
        c2, f2 = self.sa2(c1, f1)
        out = self.head(self.glob(c2, f2))
        return torch.cat([out[:, :3] * DT_UNIT, out[:, 3:] * DR_UNIT], dim=1)


def opn_loss(pred: Tensor, gt: Tensor) -> tuple[Tensor, dict[str, float]]:
    """Paper: L = RMSE(dt) + (1 - cos(dt, dt*)) + RMSE(dr), RMSEs in network units."""
    dt, dt_gt = pred[:, :3] / DT_UNIT, gt[:, :3] / DT_UNIT
    dr, dr_gt = pred[:, 3:] / DR_UNIT, gt[:, 3:] / DR_UNIT
    l_t = torch.sqrt(((dt - dt_gt) ** 2).sum(dim=1).mean() + 1e-12)
    l_cos = (1 - F.cosine_similarity(dt, dt_gt, dim=1, eps=1e-6)).mean()
    l_r = torch.sqrt(((dr - dr_gt) ** 2).sum(dim=1).mean() + 1e-12)
    return l_t + l_cos + l_r, {"l_trans": l_t.item(), "l_cos": l_cos.item(), "l_rot": l_r.item()}
