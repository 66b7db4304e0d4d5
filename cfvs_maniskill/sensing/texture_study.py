"""How a stereo matcher's disparity noise and fill rate follow the image texture it is given,
measured with OpenCV's semi-global matcher (SGBM, Hirschmueller 2008) on synthetic stereo
pairs of a fronto-parallel plane.

The passive-stereo model (`sensing/depth.py`) needs two curves no datasheet gives: how much
the disparity noise grows, and how many pixels fail to match, as a surface's texture signal
(albedo x texture contrast, relative to the imager's noise) falls. SAPIEN 3's own stereo
pipeline needs CUDA; this study runs a real matcher on CPU instead. Each pair is a textured
plane (band-limited noise of RMS contrast `c` around mean grey `a`), the right view shifted
by a known sub-pixel disparity (an exact Fourier shift), both with the imager's noise and
8-bit quantisation. The curves are written to `results/texture_study/` and the profiles'
`texture_noise_*` / `texture_fill_*` numbers are read off them (docs/sensing.md).

    python -m cfvs_maniskill.sensing.texture_study --out results/texture_study
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import tyro


@dataclass
class StudyConfig:
    """Sweep the texture signal of a plane and measure SGBM's noise and fill."""

    out: Path = Path("results/texture_study")
    """Folder for curves.json and the figure."""
    imager_noise: float = 0.01
    """The imagers' noise, fraction of full scale (assumed: ~40 dB, a global-shutter CMOS
    imager in indoor light)."""
    disparity: tuple[float, float] = (20.0, 30.0)
    """Range of the plane's true disparity, pixels, drawn per pair so that the matcher's
    sub-pixel bias (pixel locking) counts as the error it is (a D405 at 848 x 480 sees
    27-40 cm as 20-30 px)."""
    block: int = 7
    """SGBM matching window, pixels (assumed: a 7 x 7 window, a common choice)."""
    seeds: int = 8
    """Pairs per texture level."""
    size: tuple[int, int] = (120, 200)
    """Image height, width, pixels."""


def texture(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    """Unit-RMS band-limited noise: white noise low-passed at about one pixel, so the
    texture has detail down to the imager's resolution (a printed or machined pattern)."""
    h, w = shape
    white = rng.standard_normal((h, w))
    fy = np.fft.fftfreq(h)[:, None]
    fx = np.fft.fftfreq(w)[None, :]
    low = np.exp(-(fx**2 + fy**2) / (2 * 0.18**2))
    t = np.real(np.fft.ifft2(np.fft.fft2(white) * low))
    return t / t.std()


def shifted(t: np.ndarray, d: float) -> np.ndarray:
    """t sampled at x + d along each row (exact for band-limited t, periodic in x)."""
    fx = np.fft.fftfreq(t.shape[1])[None, :]
    return np.real(np.fft.ifft(np.fft.fft(t, axis=1) * np.exp(2j * np.pi * fx * d), axis=1))


def measure(signal: float, cfg: StudyConfig, seed: int) -> tuple[float, float]:
    """(fill, RMS disparity error of the matched pixels) for texture signal `signal`
    (mean grey x RMS contrast, fraction of full scale) on one pair."""
    import cv2

    rng = np.random.default_rng(seed)
    true_d = cfg.disparity[0] + (cfg.disparity[1] - cfg.disparity[0]) * rng.random()
    t = texture(rng, cfg.size)
    mean = 0.5
    c = signal / mean
    left = mean * (1 + c * t)
    right = mean * (1 + c * shifted(t, true_d))
    imgs = []
    for im in (left, right):
        im = im + rng.standard_normal(im.shape) * cfg.imager_noise
        imgs.append(np.clip(np.round(im * 255), 0, 255).astype(np.uint8))
    b = cfg.block
    sgbm = cv2.StereoSGBM_create(
        minDisparity=0,
        numDisparities=64,
        blockSize=b,
        P1=8 * b * b,
        P2=32 * b * b,
        disp12MaxDiff=1,
        uniquenessRatio=10,
        speckleWindowSize=0,
        mode=cv2.STEREO_SGBM_MODE_SGBM,
    )
    disp = sgbm.compute(imgs[0], imgs[1]).astype(np.float32) / 16.0
    m = 64 + b
    d = disp[b:-b, m:-b]
    ok = d >= 0
    err = d[ok] - true_d
    inlier = np.abs(err) < 2.0  # a gross mismatch is a wrong return, not noise
    fill = float((ok.sum() - (~inlier).sum()) / ok.size)
    rms = float(np.sqrt(np.mean(err[inlier] ** 2))) if inlier.any() else float("nan")
    return fill, rms


def fit(rows: list[dict]) -> dict:
    """The model's three numbers from the measured curves (docs/sensing.md):
    noise(snr) = floor * sqrt(1 + (noise_snr / snr)^2), least squares on the levels where
    at least a tenth of the pixels matched; fill(snr) = Phi(ln(snr / fill_snr) / spread),
    least squares on the probit of the fill between 2% and 98%."""
    from scipy.optimize import least_squares
    from scipy.stats import norm

    snr = np.array([r["snr"] for r in rows])
    rms = np.array([r["rms"] for r in rows])
    fill = np.array([r["fill"] for r in rows])
    use = fill >= 0.1
    floor = float(np.median(rms[snr >= 5]))

    def noise_res(p):
        return np.log(floor * np.sqrt(1 + (p[0] / snr[use]) ** 2)) - np.log(rms[use])

    noise_snr = float(least_squares(noise_res, [0.5], bounds=([1e-3], [10.0])).x[0])
    band = (fill > 0.02) & (fill < 0.98)
    slope, icpt = np.polyfit(np.log(snr[band]), norm.ppf(fill[band]), 1)
    return dict(
        noise_floor_px=floor,
        texture_noise_snr=noise_snr,
        texture_fill_snr=float(np.exp(-icpt / slope)),
        texture_fill_spread=float(1.0 / slope),
    )


def main(cfg: StudyConfig) -> None:
    from tqdm import tqdm

    signals = np.geomspace(0.001, 0.3, 26)
    rows = []
    for s in tqdm(signals, desc="texture levels"):
        res = [measure(float(s), cfg, k) for k in range(cfg.seeds)]
        fill = float(np.mean([r[0] for r in res]))
        rms = float(np.nanmean([r[1] for r in res]))
        rows.append(dict(signal=float(s), snr=float(s / cfg.imager_noise), fill=fill, rms=rms))
    fitted = fit(rows)
    cfg.out.mkdir(parents=True, exist_ok=True)
    config = {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(cfg).items()}
    doc = dict(config=config, fit=fitted, rows=rows)
    (cfg.out / "curves.json").write_text(json.dumps(doc, indent=1) + "\n")
    for r in rows:
        print(f"snr {r['snr']:7.2f}  fill {r['fill']:.3f}  rms {r['rms']:.3f} px")
    print(", ".join(f"{k} {v:.3f}" for k, v in fitted.items()))


if __name__ == "__main__":
    main(tyro.cli(StudyConfig))
