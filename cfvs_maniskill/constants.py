"""One source of truth for the paper's geometry (Experimental Settings). Units: metres."""

from __future__ import annotations

from pathlib import Path

PROJECT_ROOT = Path(__file__).resolve().parent.parent
"""The checkout the package runs from, if it is one: for git (provenance) only. Tasks, sensor
profiles, hole objects and weights are found through `cfvs_maniskill.resources`."""

PEG_PROFILES = ("round", "square")

ROUND_PEG_RADIUS = 0.023
"""Round peg: r = 23 mm."""
SQUARE_PEG_SIDE = 0.046
"""Square peg: 46 x 46 mm."""
PEG_LENGTH = 0.100
"""Both pegs are 100 mm long, from the flange to the tip."""

DEFAULT_CLEARANCE = 0.004
"""Hole minus peg, diametral: round hole r = 25 mm, square hole 50 mm (paper: 4 mm)."""
DEFAULT_HOLE_DEPTH = 0.045
"""Hole depth in every object (paper: 45 mm)."""

DEFAULT_SEARCH_RADIUS = 0.008
"""The compliant search's spiral radius, m, on every command (`--search-radius`; 0 = the
paper's plain insertion)."""

PRE_INSERT_HEIGHT = 0.03
"""Pre-insertion pose: the peg tip this far above the hole's opening on its axis. Every
agent servos to it before inserting; the data labels and the fine stage's goal use it."""
INSERT_OVERSHOOT = 0.01
"""The insertion commands the tip this far below the hole's bottom, so that contact (not a
position target reached in mid-air) ends it."""

SUCCESS_TIP_TOLERANCE = 0.005
"""Success: the peg tip within 5 mm (along the hole axis) of the hole's bottom ..."""
SUCCESS_WALL_PENETRATION = 0.00005
"""... the peg's full section inside the hole's walls, with this much slack for the
simulated contacts (a seated peg in a 4 mm fit ends within 0.003 mm of its wall; tight
fits sometimes end 0.1-0.3 mm into it, which is not an insertion of that fit:
benchmarks/penetration.py) ..."""
SUCCESS_TILT_MARGIN_DEG = 0.5
"""... and the peg's axis within the tilt the hole allows (its clearance across its
depth: 5.1 deg at 4 mm, 0.64 deg at 0.5 mm) plus this margin."""

MIN_WALL = 0.003
"""Thinnest wall left between the hole and the body's side."""
MIN_FLOOR = 0.003
"""Thinnest floor left under the hole's bottom."""


def peg_half_extent(profile: str) -> float:
    """Half width of the peg's cross-section (radius for round, half side for square)."""
    return ROUND_PEG_RADIUS if profile == "round" else SQUARE_PEG_SIDE / 2


def hole_half_extent(profile: str, clearance: float) -> float:
    """Half width of the hole's cross-section: peg + half the diametral clearance."""
    return peg_half_extent(profile) + clearance / 2
