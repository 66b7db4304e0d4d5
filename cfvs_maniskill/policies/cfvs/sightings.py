"""The fine stage's estimate of the hole: every look's measurement of one hole that does not
move, fused, instead of the last look alone.

Each fine look measures the hole frame in the world: the opening fitted on its face
(perception/opening.py, a few tenths of a millimetre) or, where the fit finds no opening in
that view, OPN's position (1-3 mm, and further off the further the peg is from where it
was trained to look). Taken one at a time, a look that sees no opening undoes the one
before that did, and the peg moves between the two until the loop's iterations run out.
Here the hole's position is the inverse-variance weighted mean of the looks of the surest
kind seen so far (each look's spread growing with the move it asks for): once the opening
is fitted, OPN's position alone moves it no more (on the development bodies under the D435
OPN alone was 7-25 mm off where a fit was under 1 mm). Its orientation is that of the
look of the surest kind with the smallest spread (the fit turns a square onto its walls).
The fit itself reads the points of the last few looks: a passive stereo camera on a plain
part puts too few on the opening's edge in one.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

SIGMA_FIT = 0.0005
"""A look whose opening was fitted on its face: its position's spread (m; the fit's
lateral error p50 0.4-0.6 mm on fine views of the development bodies `manifolds` under
`d435` and `realistic`)."""
SIGMA_OPN = 0.0015
"""A look from OPN's position alone (m; its error p50 / p90 1.3 / 2.6 mm on the same
views, the peg at the pose it was trained to reach)."""
SPREAD_PER_MOVE = 0.25
"""Either kind's spread grows by this share of the move the look asks for: further from
the pose OPN was trained to reach, its estimate is further off, and the fit, which starts
from it and moves it 6 mm at most, with it."""

LOOKS = 3
"""The opening is fitted to the points of this many latest looks."""


@dataclass
class Sightings:
    """The looks of one episode's fine stage."""

    positions: list[np.ndarray] = field(default_factory=list)
    weights: list[float] = field(default_factory=list)
    fitted: list[bool] = field(default_factory=list)
    best: tuple[bool, float, np.ndarray] | None = None
    """(not fitted, spread, rotation) of the look of the surest kind with the least spread."""
    clouds: list[np.ndarray] = field(default_factory=list)

    def cloud(self, world: np.ndarray) -> np.ndarray:
        """A look's world points `world` with those of the LOOKS - 1 looks before it (the
        hole does not move; each look's noise and shadows are its own)."""
        self.clouds = [*self.clouds, world][-LOOKS:]
        return np.concatenate(self.clouds)

    def add(self, H: np.ndarray, fitted: bool, move: float) -> np.ndarray:
        """Take look `H` (4x4 hole frame in the world), `fitted` on the opening or from
        OPN's position when the peg is `move` (m) from OPN's target; the fused frame."""
        sigma = float(np.hypot(SIGMA_FIT if fitted else SIGMA_OPN, SPREAD_PER_MOVE * move))
        self.positions.append(H[:3, 3].copy())
        self.weights.append(1.0 / sigma**2)
        self.fitted.append(fitted)
        if self.best is None or (not fitted, sigma) <= self.best[:2]:
            self.best = (not fitted, sigma, H[:3, :3].copy())
        out = np.eye(4)
        out[:3, :3] = self.best[2]
        surest = np.array(self.fitted) == any(self.fitted)
        out[:3, 3] = np.average(
            np.array(self.positions)[surest], axis=0, weights=np.array(self.weights)[surest]
        )
        return out

    def __len__(self) -> int:
        return len(self.positions)
