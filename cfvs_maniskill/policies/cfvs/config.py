"""CFVS's configuration: the paper's stages and the components that refine them, each a
switch; REQUIRES says which switch refines which, ABLATIONS names the agent that changes
one (`cfvs_<name>`). Light: listing the agents needs no network or simulator."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from cfvs_maniskill import resources

WEIGHTS_DIR = resources.bundled("agents") / "cfvs"


@dataclass
class CFVSConfig:
    coarse_to_fine: bool = True
    """Run the fine OPN loop after the coarse move (ablation: False)."""
    confidence_map: bool = True
    """Weight keypoint candidates by OAKN's confidence (ablation: uniform mean)."""
    augmentation: bool | None = None
    """None: the shipped weights (the square nets are trained without the paper's
    scaling-and-bending augmentation). True / False: the files trained with / without it."""
    max_fine_iterations: int = 8
    """Algorithm 2's repeat limit."""
    tol_translation: float = 0.001
    """e_t: stop servoing when the predicted |dt| is below this, metres (the paper gives
    no value; docs/cfvs.md has how 1 mm was chosen)."""
    tol_rotation_deg: float = 1.5
    """e_r: ... and the predicted |dr| below this, degrees."""
    fine_votes: int = 3
    """OPN predictions (on independent random point subsets) averaged per fine step."""
    vote_gate: float = 0.003
    """A fine step first runs one vote; when it asks for a move longer than this (metres),
    the peg moves on it alone: far from the pose one vote's error (~1 mm) is small against
    the move and the next step corrects it. Nearer, the other `fine_votes - 1` run too and
    all are averaged, so the step that decides to stop sees the full average. 0: every
    step averages all votes."""
    final_correction: bool = True
    """When the offset is below (e_t, e_r), move by it once more, then insert (no new
    observation: it is the move Algorithm 2's next iteration would start with). False: the
    paper's Algorithm 2, which inserts from where the last check was made, leaving up to
    e_t of the offset it measured."""
    rim_plane: bool = True
    """Refine OPN's estimate by the geometry of the face round the opening it points at
    (`refine`): in 6-DoF the hole's axis becomes the face's normal (perception/rim.py: the
    plane of the surface next to the opening; 3- and 4-DoF holes are upright); OPN still
    gives where the hole is. False: the paper's fine stage (the `cfvs_no_rim` ablation)."""
    opening_fit: bool = True
    """With `rim_plane`: place the opening on the face the wrist cloud shows round it (its
    shape and size are the task's nominal ones). Coarse: OAKN's estimate moved onto the
    opening searched for within 4 cm of it (perception/opening_search.py), when one place
    stands out. Fine: at the level of the face just outside it (walls and flanges beside
    the opening pull OPN's height up), centred on its edge and walls (a square's sides, a
    round hole's circle), a square turned onto its walls (perception/opening.py), searched
    for as in the coarse stage where OPN's estimate is not near it. Each fine look is one
    measurement of a hole that does not move: the opening is fitted to the points of the
    last `sightings.LOOKS` looks, and the hole's position is the weighted mean of every
    look's (policies/cfvs/sightings.py). False: OAKN's and OPN's positions and yaw, each
    look on its own."""
    clear_view: bool = True
    """4- and 6-DoF square holes: of the four equivalent approach yaws, take the one
    nearest the tool's own whose camera has a clear line of sight to the opening from the
    pre-insertion pose (perception/view.py; the coarse cloud says what stands over the
    face). False: always the nearest."""
    look_again: bool = True
    """Look again from a better view where one look cannot be trusted: OAKN's estimate made
    from further than 20 cm is taken again from 15 cm (agent.NEAR_VIEW), the look put on
    an opening (`opening_fit`), then the one whose candidates lie closer together
    (`keypoint_spread`), kept; and when a fine look does not
    show the estimated opening (the opening nearer than the camera's minimum range, a wall
    between the camera and the opening: agent.MIN_AT_OPENING) or three in a row fit no
    opening (agent.UNFITTED_LOOKS), look again from another view of the same estimate:
    2 cm further back, then (a square in 4/6-DoF) turned about the hole's axis, which
    puts the camera on another side of the opening, up to three turns. When no view shows
    it, insert at the estimate. False: insert there at once."""
    calibration: bool = True
    """Correct the camera from what the robot knows is in view, measured on the coarse view
    and applied to every view of the episode: the table plane, at a known height, gives the
    depth scale and two mount angles (perception/table_calibration.py); the peg, where the
    mount shows it (`tip_view`), moves the cloud so the peg sits where the arm holds it
    (perception/peg.py), so the hole is placed relative to the tip as the camera sees both.
    False: the cloud as the camera reports it."""
    weights_dir: Path = WEIGHTS_DIR

    def __post_init__(self) -> None:
        for switch, needs in REQUIRES.items():
            if getattr(self, switch) and not getattr(self, needs):
                raise ValueError(
                    f"CFVSConfig: {switch}=True needs {needs}=True (it refines what "
                    f"{needs} computes); set {switch}=False too, or build it with "
                    f"CFVSConfig.without('{needs}')"
                )

    @classmethod
    def without(cls, switch: str, **fields) -> CFVSConfig:
        """The default config with `switch` off, and with it every switch that needs it."""
        off = {switch}
        while grown := {s for s, n in REQUIRES.items() if n in off} - off:
            off |= grown
        return cls(**{s: False for s in off}, **fields)


REQUIRES = {
    "rim_plane": "coarse_to_fine",
    "final_correction": "coarse_to_fine",
    "look_again": "coarse_to_fine",
    "opening_fit": "rim_plane",
}
"""Switch -> the switch it refines: a config with the first on and the second off is
refused, since the first would silently do nothing."""

ABLATIONS: dict[str, tuple[str, str]] = {
    # The paper's Table IV.
    "no_c2f": ("coarse_to_fine", "insert right after OAKN's coarse move"),
    "no_map": ("confidence_map", "keypoints as the uniform mean of the candidates"),
    "aug": ("augmentation", "networks trained with the paper's augmentation"),
    # The paper's own fine stage, and one per component of ours (docs/cfvs.md).
    "no_rim": ("rim_plane", "the paper's fine stage: OPN's estimate, no face geometry"),
    "no_opening": ("opening_fit", "the opening's height, centre (a square's yaw) from OPN"),
    "fixed_yaw": ("clear_view", "the approach yaw nearest the tool's, whatever blocks the view"),
    "no_look_again": ("look_again", "one coarse look; insert when a fine look sees nothing"),
    "no_final_correction": ("final_correction", "insert from the last check (Algorithm 2)"),
    "no_calibration": ("calibration", "the cloud as reported, not set by the table and peg"),
}
"""`cfvs_<name>`: CFVS with one component changed (the switch, then what it says)."""


def ablation_config(name: str) -> CFVSConfig:
    """The config of ablation `name` (a key of ABLATIONS): its switch flipped from the
    default, with the switches that need it (REQUIRES) off too."""
    switch, _ = ABLATIONS[name]
    if switch == "augmentation":  # the shipped nets are trained without it: turn it on
        return CFVSConfig(augmentation=True)
    return CFVSConfig.without(switch)
