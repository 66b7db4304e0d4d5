"""The two pieces both insertions share: the spiral search on the rim and the stall test."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class SpiralSearch:
    """Archimedean spiral r = pitch * angle / 2pi, walked at `speed` out to `radius`.

    A real cell's search pattern: the peg keeps pressing lightly on the rim and slides
    along the spiral; turns `pitch` apart skip no position the peg could drop in from."""

    pitch: float
    speed: float
    radius: float
    stalled_at: float
    """Insertion travel where the peg stalled on the rim (the drop is measured from it)."""
    min_radius: float = 1e-4
    """Radius used for the angular step near the centre. The paper-era 1e-4 m makes the
    first step jump out to ~1.5 pitches (kept for the 4 mm tasks, whose results were measured
    with it); the force-guided insertion uses a quarter pitch and so starts at the centre."""
    angle: float = 0.0

    def step(self, dt: float) -> np.ndarray | None:
        """Advance one control step; the offset in the tool's frame, None once past `radius`."""
        r = max(self.pitch * self.angle / (2 * np.pi), self.min_radius)  # no 0-division at r=0
        self.angle += self.speed * dt / r
        r = self.pitch * self.angle / (2 * np.pi)
        if r > self.radius:
            return None
        return np.array([r * np.cos(self.angle), r * np.sin(self.angle), 0.0])


def stalled(history: list[float], steps: int, progress: float = 0.0005) -> bool:
    """True when the travel in `history` grew less than `progress` m over the last `steps`."""
    return len(history) > steps and history[-1] - history[-1 - steps] < progress
