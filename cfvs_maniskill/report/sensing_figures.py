"""The depth models' figures as the code gives them, for docs/sensing.md: each stereo
profile's depth noise and fill on a plate of each material, square-on, at 15 / 30 / 50 cm,
measured by running the model (`apply_stereo`) on it, and its occlusion band beside a rim.

    python -m cfvs_maniskill.report.sensing_figures   # rewrites the table in docs/sensing.md
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import tyro

from cfvs_maniskill.report.tables import replace_marked
from cfvs_maniskill.robots.ur5 import CAMERA_FOV
from cfvs_maniskill.sensing import surfaces
from cfvs_maniskill.sensing.depth import EpisodeDepth, apply_stereo, grid_points, occluded
from cfvs_maniskill.sensing.profile import available_profiles, load_profile

DOC = Path(__file__).resolve().parents[2] / "docs" / "sensing.md"
MARK = "sensing"
"""The table sits between `<!-- report:sensing begin/end -->` in DOC."""
SIDE = 96
FOCAL = 64 / float(np.tan(CAMERA_FOV / 2))
"""The wrist camera's render: focal length in pixels (128 px over 70 deg)."""
ALBEDO = 0.6
"""A mid-grey part."""
DISTANCES = (0.15, 0.30, 0.50)


def plate(model, z: float, material: str, seed: int = 0) -> tuple[float, float]:
    """(RMS depth error m, fill) of the model on a square-on plate of `material` at z: the
    central pixels, one episode's fixed draws plus one observation's."""
    K = np.array([[FOCAL, 0.0, SIDE / 2], [0.0, FOCAL, SIDE / 2], [0.0, 0.0, 1.0]])
    pts = grid_points(np.full((SIDE, SIDE), z, np.float32), K)
    rng = np.random.default_rng([seed, 1])
    episode = EpisodeDepth(
        fixed_noise=rng.standard_normal((SIDE, SIDE), dtype=np.float32),
        fixed_uniform=rng.random((SIDE, SIDE), dtype=np.float32),
    )
    albedo = np.full((SIDE, SIDE), ALBEDO, np.float32)
    contrast = np.full((SIDE, SIDE), surfaces.MATERIALS[material], np.float32)
    out, ok = apply_stereo(
        pts, np.ones((SIDE, SIDE), bool), model, np.random.default_rng(seed), 1 / FOCAL,
        (albedo, contrast), episode,
    )  # fmt: skip
    c = slice(SIDE // 2 - 16, SIDE // 2 + 16)
    inner, dz = ok[c, c], out[c, c, 2] - z
    rms = float(np.sqrt(np.mean(dz[inner] ** 2))) if inner.any() else float("nan")
    return rms, float(inner.mean())


def band_px(model, near: float = 0.14, far: float = 0.185) -> float:
    """Width of the occlusion band (render pixels) beside a rim at `near` over a floor at
    `far` (a 45 mm deep hole seen from the pre-insertion pose)."""
    z = np.full((64, 128), far, np.float32)
    z[:, 64:] = near
    return float(occluded(z, np.ones(z.shape, bool), FOCAL, model.baseline).sum(axis=1).mean())


def table() -> str:
    rows = [
        "| profile | material | RMS depth error at 15 / 30 / 50 cm | fill at 15 / 30 / 50 cm "
        "| occlusion band, 14 cm rim over an 18.5 cm floor |",
        "|---|---|---|---|---|",
    ]
    for name in available_profiles():
        profile = load_profile(name)
        model = profile.depth
        if model.model != "stereo":
            continue
        materials = ("plain", "printed") if model.imager_noise > 0 else ("any",)
        if profile.surfaces.part_material is not None:
            materials = (profile.surfaces.part_material,)
        for material in materials:
            stats = [plate(model, z, "plain" if material == "any" else material) for z in DISTANCES]
            errs = " / ".join("-" if np.isnan(s[0]) else f"{1000 * s[0]:.2f}" for s in stats)
            fills = " / ".join(f"{s[1]:.2f}" for s in stats)
            band = "-"
            if model.occlusion:
                px = band_px(model)
                band = f"{px:.0f} px ({1000 * px * 0.185 / FOCAL:.1f} mm on the floor)"
            rows.append(f"| `{name}` | {material} | {errs} mm | {fills} | {band} |")
    return "\n".join(rows)


@dataclass
class FiguresArgs:
    """Rewrite the stereo profiles' noise table in docs/sensing.md from the code."""

    doc: Path = DOC
    """The file holding the table between its markers."""


def main(args: FiguresArgs) -> None:
    args.doc.write_text(replace_marked(args.doc.read_text(), MARK, table(), str(args.doc)))
    print(f"wrote the stereo profiles' figures into {args.doc}")


if __name__ == "__main__":
    main(tyro.cli(FiguresArgs))
