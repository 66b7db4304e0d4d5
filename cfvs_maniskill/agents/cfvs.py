"""The CFVS agent (paper, Fig. 2): OAKN coarse move, OPN fine visual servoing, insertion.

1. Coarse (open loop): OAKN votes the hole's keypoints from the wrist cloud; Algorithm 1
   turns them into the hole frame; the peg moves to the pre-insertion pose above it.
2. Fine (closed loop, Algorithm 2): OPN reads the cloud cropped around the end-effector and
   returns the offset (dt, dr) to the pre-insertion pose; the peg moves by it; repeat until
   the offset is below (e_t, e_r) or `max_fine_iterations` is reached. In 6-DoF (beyond
   the paper, `rim_plane`) the offset's tilt is replaced by the normal of the face around
   the opening OPN points at (perception/rim.py): OPN gives where the hole is, the face
   gives its axis (3- and 4-DoF holes are upright); the opening seen on that face then
   gives its centre, and a square's yaw (`opening_fit`, perception/opening.py), OPN's
   estimate the place to look.
3. Insert along the tool axis (shared executor, force-bounded).

Every component is a CFVSConfig switch; ABLATIONS names the agent that changes one
(`cfvs_no_c2f`: insert right after the coarse move, `cfvs_no_map`: uniform keypoint mean,
`cfvs_aug`: nets trained with the paper's augmentation, `cfvs_no_rim`: the paper's fine
stage, ...); REQUIRES says which switch refines which, checked when a config is built.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from cfvs_maniskill import resources
from cfvs_maniskill.agents.base import Action, Agent, Observation
from cfvs_maniskill.agents.interface import TaskSpec, camera_in_tcp, insertion_pose
from cfvs_maniskill.constants import PRE_INSERT_HEIGHT, hole_half_extent
from cfvs_maniskill.nets.checkpoint import WeightsTableError, load_weights
from cfvs_maniskill.nets.oakn import weighted_keypoints
from cfvs_maniskill.perception import labels as L
from cfvs_maniskill.perception.clouds import (
    MIN_OBJECT_POINTS,
    fine_crop,
    sample_fixed,
    tool_to_world,
    valid_world_points,
    world_object_points,
)
from cfvs_maniskill.perception.opening import MIN_LEVEL_POINTS, face_height, fit_opening
from cfvs_maniskill.perception.rim import align_axis, rim_normal
from cfvs_maniskill.perception.table_calibration import IDENTITY, correction_from_table
from cfvs_maniskill.perception.view import approach_yaws, clear_view_yaw
from cfvs_maniskill.task_dof import constrain
from cfvs_maniskill.validation import read_yaml

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
    (`refine`): in 6-DoF the hole's axis becomes the face's normal (perception/rim.py; 3-
    and 4-DoF holes are upright); OPN still gives where the hole is. False: the paper's
    fine stage (the `cfvs_no_rim` ablation)."""
    rim_parallel_planes: bool = True
    """6-DoF: check the face's least-median plane against a fit of the ring's parallel planar
    patches (perception/rim.py) and take the latter where they disagree: beside a rib or a
    step the face may hold under half the ring. False: the least-median plane alone."""
    rim_square_ring: bool = True
    """6-DoF square holes: the ring follows the opening's sides (from OPN's yaw), starting 4
    mm outside them. False: a round ring beyond the opening's corners, which can fall off a
    small face (a boss, a hub) onto whatever is beyond."""
    rim_narrow_ring: bool = True
    """6-DoF: the rim fit tries a 10 mm ring before the 20 mm one and keeps it when the
    noise measured on it predicts a normal within 0.1 deg (perception/rim.py): beside a step
    round the opening (a counterbore) the wide ring reaches the step. False: the 20 mm
    ring always."""
    opening_fit: bool = True
    """With `rim_plane`: move the estimate in the face's plane (and turn a square about its
    axis) onto the opening the wrist cloud shows, from the face's edge and the walls in
    view (perception/opening.py; the hole's size is the task's nominal one): a square's
    sides, a round hole's circle. False: OPN's position and yaw."""
    face_height: bool = True
    """With `rim_plane`: put the hole's opening at the level of the face seen just outside
    it (perception/opening.face_height) instead of OPN's height, which walls and flanges
    beside the opening pull up. False: OPN's height."""
    face_guard: bool = True
    """With `face_height`: when OPN's new estimate has no face round its opening in the
    cloud (fewer than MIN_LEVEL_POINTS 1-6 mm outside it) after an estimate that had one,
    the fine loop stops and the peg is inserted from where it is, the pose of the last
    estimate the face supported: beside a step OPN can jump to another surface and back.
    False: every estimate is taken."""
    clear_view: bool = True
    """4- and 6-DoF square holes: of the four equivalent approach yaws, take the one
    nearest the tool's own whose camera has a clear line of sight to the opening from the
    pre-insertion pose (perception/view.py; the coarse cloud says what stands over the
    face). False: always the nearest."""
    turn_when_blind: bool = True
    """4- and 6-DoF: when a fine look sees nothing round the peg (a wall between the camera
    and the opening, or a step nearer than the camera's minimum range fills its view),
    move to the same pre-insertion pose turned about the hole's axis, which puts the
    camera on another side of the opening, up to three turns. False: give up there. A 3-DoF
    peg keeps its yaw, so it gives up either way."""
    table_calibration: bool = True
    """Correct the camera's depth scale and two of its mount angles once per episode, from
    the table plane in the coarse view, whose height the robot knows
    (perception/table_calibration.py). False: the cloud as the camera reports it."""
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


MAX_TURNS = 3
"""`turn_when_blind` tries each of the other three yaws of a square at most once."""

REQUIRES = {
    "rim_plane": "coarse_to_fine",
    "final_correction": "coarse_to_fine",
    "turn_when_blind": "coarse_to_fine",
    "opening_fit": "rim_plane",
    "face_height": "rim_plane",
    "face_guard": "face_height",
    "rim_parallel_planes": "rim_plane",
    "rim_square_ring": "rim_plane",
    "rim_narrow_ring": "rim_plane",
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
    "opn_height": ("face_height", "the opening's height from OPN, not from the face"),
    "no_face_guard": ("face_guard", "every fine estimate taken, with or without a face"),
    "no_opening": ("opening_fit", "the opening's centre (a square's yaw) from OPN alone"),
    "no_parallel": ("rim_parallel_planes", "the face's plane by least median of squares alone"),
    "wide_ring": ("rim_narrow_ring", "the rim fit on the 20 mm ring always"),
    "round_ring": ("rim_square_ring", "a round rim ring beyond a square opening's corners"),
    "fixed_yaw": ("clear_view", "the approach yaw nearest the tool's, whatever blocks the view"),
    "no_turn": ("turn_when_blind", "give up when a fine look sees nothing round the peg"),
    "no_final_correction": ("final_correction", "insert from the last check (Algorithm 2)"),
    "no_table_calibration": ("table_calibration", "the cloud as reported, not set by the table"),
}
"""`cfvs_<name>`: CFVS with one component changed (the switch, then what it says)."""


def ablation_config(name: str) -> CFVSConfig:
    """The config of ablation `name` (a key of ABLATIONS): its switch flipped from the
    default, with the switches that need it (REQUIRES) off too."""
    switch, _ = ABLATIONS[name]
    if switch == "augmentation":  # the shipped nets are trained without it: turn it on
        return CFVSConfig(augmentation=True)
    return CFVSConfig.without(switch)


def weights_for(
    task: str, peg: str, weights_dir: Path, augmentation: bool | None = None
) -> dict[str, Path]:
    """The OAKN / OPN files for a task: `tasks.yaml` in the weights folder maps task names;
    tasks it does not list (e.g. new task files) use `<peg>/oakn.pt`, `<peg>/opnv.pt`.
    With `augmentation` set, the file trained that way: the shipped one if its .json says
    so, else its `_aug` / `_noaug` sibling."""
    table_file = weights_dir / "tasks.yaml"
    table = read_yaml(table_file, WeightsTableError) if table_file.is_file() else {}
    if not isinstance(table, dict | None):
        raise WeightsTableError(table_file, "<top>", "expected a mapping of task names")
    entry = (table or {}).get(task) or {"oakn": f"{peg}/oakn.pt", "opn": f"{peg}/opnv.pt"}
    for net in ("oakn", "opn"):
        if not isinstance(entry, dict) or not isinstance(entry.get(net), str):
            raise WeightsTableError(
                table_file, f"{task}.{net}", f"expected the path of a {net} file, got {entry!r}"
            )
    out = {}
    for net in ("oakn", "opn"):
        p = weights_dir / entry[net]
        if augmentation is not None and trained_with_augmentation(p) is not augmentation:
            p = p.with_name(p.stem + ("_aug.pt" if augmentation else "_noaug.pt"))
        out[net] = p
    return out


def trained_with_augmentation(weights: Path) -> bool | None:
    """From the training record beside a weights file (None: no record)."""
    record = weights.with_suffix(".json")
    if not record.is_file():
        return None
    args = json.loads(record.read_text()).get("train_args", {})
    return str(args.get("augment", "True")) == "True"


class CFVSAgent(Agent):
    name = "cfvs"
    obs_mode = "pointcloud"

    def __init__(self, task: TaskSpec, cfg: CFVSConfig | None = None):
        self.task = task
        self.cfg = cfg or CFVSConfig()
        self.peg = task.peg
        files = weights_for(task.name, task.peg, self.cfg.weights_dir, self.cfg.augmentation)
        self.oakn, self.oakn_meta = load_weights(files["oakn"], "oakn", task.peg)
        self.opn, self.opn_meta = load_weights(files["opn"], ("opnv", "opn"), task.peg)
        self.max_decisions = 2 + self.cfg.max_fine_iterations + MAX_TURNS
        self.rng = np.random.default_rng(0)
        self.stage = "coarse"
        self.fine_steps = 0
        self.had_face = False
        self.correction = IDENTITY

    def reset(self, seed: int) -> None:
        self.stage, self.fine_steps = "coarse", 0
        self.correction = IDENTITY  # the camera's errors change with the episode
        self.had_face = False  # whether any fine estimate had its face seen round it
        self.blind_x: list[np.ndarray] = []  # tool x axes whose fine look saw nothing
        self.phase, self.estimate = "", None
        # Point subsets are random; seeded per episode, so the same episode repeats exactly.
        self.rng = np.random.default_rng(seed)

    # ------------------------------------------------------------------ perception
    @torch.no_grad()
    def estimate_hole(self, pts: np.ndarray, tcp: np.ndarray) -> np.ndarray | None:
        """OAKN + Algorithm 1: the hole's world frame from one wrist view's tool-frame object
        points `pts` (`object_points`), or None."""
        if len(pts) < MIN_OBJECT_POINTS:
            return None
        x = torch.from_numpy(sample_fixed(pts, int(self.oakn_meta["points"]), self.rng))[None]
        offsets, logits = self.oakn(x)
        w = torch.sigmoid(logits) if self.cfg.confidence_map else None
        k, _ = weighted_keypoints(x, offsets, w)
        k_world = tool_to_world(k[0].numpy().astype(np.float64), tcp)
        return L.hole_frame_from_keypoints(k_world.astype(np.float64))

    @torch.no_grad()
    def predict_offset(self, pts: np.ndarray) -> np.ndarray | None:
        """OPN on the fine crop `pts` (tool frame): (dt, dr) in the tool frame to the
        pre-insertion pose, or None."""
        if len(pts) < MIN_OBJECT_POINTS:
            return None
        first = self._votes(pts, 1)
        if self.cfg.fine_votes <= 1 or (
            self.cfg.vote_gate > 0 and np.linalg.norm(first[0, :3]) > self.cfg.vote_gate
        ):
            return first[0]
        votes = np.concatenate([first, self._votes(pts, self.cfg.fine_votes - 1)])
        return votes.mean(axis=0)

    def _votes(self, pts: np.ndarray, count: int) -> np.ndarray:
        """(count, 6) offsets from OPN on `count` independent random subsets of `pts`."""
        n = int(self.opn_meta["points"])
        x = torch.from_numpy(np.stack([sample_fixed(pts, n, self.rng) for _ in range(count)]))
        if self.opn_meta["net"] == "opn":  # the paper's OPN: offsets straight from the net
            return self.opn(x).numpy().astype(np.float64)
        # opnv: vote the target keypoints, then turn them into the offset.
        offsets, logits = self.opn(x)
        k, _ = weighted_keypoints(x, offsets, torch.sigmoid(logits))
        return np.array([L.fine_action_from_keypoints(ki.numpy()) for ki in k], np.float64)

    def refine(
        self, a: np.ndarray, pts: np.ndarray, tcp: np.ndarray
    ) -> tuple[np.ndarray, str, bool | None]:
        """OPN's offset `a` refined by the geometry of the face round the opening it points
        at: in 6-DoF the hole's axis from the face's normal (`rim_plane`; 3- and 4-DoF holes
        are upright), then the centre (and a square's yaw) from the opening seen on that
        face (`opening_fit`) and its height from the face (`face_height`). Returns the
        offset, where it came from, and whether the face was seen round the opening (None:
        not measured); (a, "OPN offset", None) when the 6-DoF ring gives no face."""
        T = L.apply_action(tcp, a)
        T = T if self.task.dof == 6 else self.constrain(T, tcp)
        H = L.hole_frame_from_pre_insertion(T)
        world = tool_to_world(pts, tcp)
        half = hole_half_extent(self.peg, self.task.clearance)
        round_opening = self.peg == "round"
        where = "upright axis"
        if self.task.dof == 6:
            n = self.rim_axis(world, H, half)
            if n is None:
                return a, "OPN offset", None
            H, where = align_axis(H, n), "axis from the rim"
        seen = (
            fit_opening(world, H, half, round_opening=round_opening)
            if self.cfg.opening_fit
            else None
        )
        where += ", OPN position" if seen is None else ", centre from the opening"
        H = H if seen is None else seen
        face_seen = None
        if self.cfg.face_height:
            level, ring_points = face_height(world, H, half, round_opening=round_opening)
            face_seen = ring_points >= MIN_LEVEL_POINTS
            if level is not None:
                H = H.copy()
                H[:3, 3] += level * H[:3, 2]
                where += ", height from the face"
        pose = insertion_pose(self.peg, H, -PRE_INSERT_HEIGHT, T)
        return L.fine_action(tcp, pose), where, face_seen

    def rim_axis(self, world: np.ndarray, H: np.ndarray, half: float) -> np.ndarray | None:
        """The hole's axis from the face round the opening of hole frame `H` (its normal,
        `rim_plane`), or None when the ring round the opening shows no face."""
        reach, square_x = half, None
        if self.peg == "square" and self.cfg.rim_square_ring:
            square_x = H[:3, 0]  # the ring follows the opening's sides
        elif self.peg == "square":
            reach *= np.sqrt(2)  # a round ring beyond the opening's corners
        return rim_normal(
            world,
            H[:3, 3],
            H[:3, 2],
            reach,
            self.rng,
            parallel_planes=self.cfg.rim_parallel_planes,
            square_x=square_x,
            narrow_first=self.cfg.rim_narrow_ring,
        )

    def approach(self, H: np.ndarray, world: np.ndarray, tcp: np.ndarray) -> np.ndarray:
        """The pre-insertion pose over hole frame `H`: at the yaw nearest the tool's own or,
        with `clear_view`, the nearest whose camera sees the opening past what stands on
        the face (`world`: the coarse view's object points)."""
        nearest = insertion_pose(self.peg, H, -PRE_INSERT_HEIGHT, tcp)
        if not (self.cfg.clear_view and self.peg == "square" and self.task.dof != 3):
            return nearest  # a 3-DoF peg keeps its yaw (task_dof.constrain)
        poses = approach_yaws(nearest, tcp[:3, 0])
        i, _ = clear_view_yaw(world, poses, camera_in_tcp(), H)
        return poses[i]

    def turn(self, tcp: np.ndarray) -> Action | None:
        """`turn_when_blind`: the current estimate's pre-insertion pose at the least wrist
        turn whose yaw is at least 45 deg from every yaw that saw nothing, or None."""
        if not self.cfg.turn_when_blind or self.task.dof == 3 or self.estimate is None:
            return None
        self.blind_x.append(tcp[:3, 0].copy())
        nearest = insertion_pose(self.peg, self.estimate, -PRE_INSERT_HEIGHT, tcp)
        for pose in approach_yaws(nearest, tcp[:3, 0]):
            if all(pose[:3, 0] @ x < np.cos(np.radians(45)) for x in self.blind_x):
                self.phase = "fine: nothing seen round the peg, the wrist turned"
                return Action.move(self.constrain(pose, tcp))
        return None

    def constrain(self, T: np.ndarray, ref: np.ndarray) -> np.ndarray:
        return constrain(self.task, T, ref)

    def calibrated_points(self, xyzw: np.ndarray, tcp: np.ndarray) -> np.ndarray:
        """The cloud's world points that saw something, with the episode's table
        calibration applied (measured on the coarse view, where most of the table is in
        sight)."""
        world = valid_world_points(xyzw)
        if not self.cfg.table_calibration:
            return world
        camera = tcp.copy()  # the tool's axes serve: the camera is fixed to the tool
        camera[:3, 3] = tcp[:3, :3] @ camera_in_tcp() + tcp[:3, 3]
        if self.stage == "coarse":
            self.correction = correction_from_table(world, camera) or IDENTITY
        return self.correction.apply(world.astype(np.float64), camera)

    # ------------------------------------------------------------------ decisions
    def act(self, observation: Observation) -> Action:
        tcp = observation.tcp_pose
        xyzw = observation.obs["pointcloud"]["xyzw"][0].cpu().numpy()
        if self.stage == "coarse":
            pts = world_object_points(self.calibrated_points(xyzw, tcp), tcp, self.peg)
            H = self.estimate_hole(pts, tcp)
            if H is None or not np.all(np.isfinite(H)):
                return Action.give_up("OAKN: the camera sees no hole object")
            self.phase, self.estimate = "coarse: OAKN keypoints -> hole frame", H
            self.stage = "fine" if self.cfg.coarse_to_fine else "insert"
            pose = self.approach(H, tool_to_world(pts, tcp), tcp)
            return Action.move(self.constrain(pose, tcp))
        if self.stage == "fine" and self.fine_steps < self.cfg.max_fine_iterations:
            pts = world_object_points(self.calibrated_points(xyzw, tcp), tcp, self.peg)
            a = self.predict_offset(fine_crop(pts))
            if a is None:
                turned = self.turn(tcp)
                return turned or Action.give_up("OPN: nothing seen around the peg")
            source = "OPN offset"
            if self.cfg.rim_plane:
                a, source, face_seen = self.refine(a, pts, tcp)
                if self.cfg.face_guard and face_seen is False and self.had_face:
                    self.stage = "insert"
                    self.phase = "fine: no face round OPN's new estimate, insert from the last"
                    return Action.insert()
                self.had_face = self.had_face or bool(face_seen)
            if self.task.dof != 6:  # measure the remaining offset in the allowed DoF only
                a = L.fine_action(tcp, self.constrain(L.apply_action(tcp, a), tcp))
            small = (
                np.linalg.norm(a[:3]) < self.cfg.tol_translation
                and np.degrees(np.linalg.norm(a[3:])) < self.cfg.tol_rotation_deg
            )
            target = L.apply_action(tcp, a)
            self.estimate = L.hole_frame_from_pre_insertion(target)
            if not small:
                self.fine_steps += 1
                self.phase = f"fine iteration {self.fine_steps}: {source}"
                return Action.move(target)
            if self.cfg.final_correction:
                self.stage = "insert"  # the next decision inserts, whatever it sees
                self.phase = f"final correction: the last {source} below (e_t, e_r)"
                return Action.move(target)
        self.phase = "insertion"
        return Action.insert()
