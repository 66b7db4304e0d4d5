"""The CFVS agent (paper, Fig. 2): OAKN coarse move, OPN fine visual servoing, insertion.

1. Coarse (open loop): OAKN votes the hole's keypoints from the wrist cloud; Algorithm 1
   turns them into the hole frame, which (beyond the paper, `opening_fit`) moves onto the
   opening the cloud shows round it (perception/opening_search.py); the peg moves to the
   pre-insertion pose above it.
2. Fine (closed loop, Algorithm 2): OPN reads the cloud cropped around the end-effector and
   returns the offset (dt, dr) to the pre-insertion pose; the peg moves by it; repeat until
   the offset is below (e_t, e_r) or `max_fine_iterations` is reached. A look that does not
   show the estimated opening (behind a wall) is not used (`look_again`). In 6-DoF (beyond
   the paper, `rim_plane`) the offset's tilt is replaced by the normal of the face around
   the opening OPN points at (perception/rim.py): OPN gives where the hole is, the face
   gives its axis (3- and 4-DoF holes are upright); the opening seen on that face then
   gives its centre, and a square's yaw (`opening_fit`, perception/opening.py), OPN's
   estimate the place to look; the looks are fused into one estimate (sightings.py).
3. Insert along the tool axis (shared executor, force-bounded).

Every component is a CFVSConfig switch; config.ABLATIONS names the agent that changes one
(`cfvs_no_c2f`: insert right after the coarse move, `cfvs_no_map`: uniform keypoint mean,
`cfvs_aug`: nets trained with the paper's augmentation, `cfvs_no_rim`: the paper's fine
stage, ...); config.REQUIRES says which switch refines which, checked when a config is built.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from cfvs_maniskill import geometry as G
from cfvs_maniskill.constants import PRE_INSERT_HEIGHT, hole_half_extent
from cfvs_maniskill.nets.checkpoint import WeightsTableError
from cfvs_maniskill.perception import labels as L
from cfvs_maniskill.perception.clouds import (
    MIN_OBJECT_POINTS,
    fine_crop,
    sample_fixed,
    tool_to_world,
    valid_world_points,
    world_object_points,
)
from cfvs_maniskill.perception.opening import face_height
from cfvs_maniskill.perception.opening_search import locate_opening, search_opening
from cfvs_maniskill.perception.peg import apply as apply_correction
from cfvs_maniskill.perception.peg import peg_correction
from cfvs_maniskill.perception.rim import align_axis, rim_normal
from cfvs_maniskill.perception.table_calibration import IDENTITY, correction_from_table
from cfvs_maniskill.perception.view import approach_yaws, clear_view_yaw, points_at_opening
from cfvs_maniskill.policies.base import Action, Agent, Observation
from cfvs_maniskill.policies.cfvs.config import CFVSConfig
from cfvs_maniskill.policies.cfvs.oakn import keypoint_spread, weighted_keypoints
from cfvs_maniskill.policies.cfvs.sightings import Sightings
from cfvs_maniskill.policies.interface import TaskSpec, insertion_pose
from cfvs_maniskill.policies.networks import load_weights
from cfvs_maniskill.task_dof import constrain
from cfvs_maniskill.validation import read_yaml

MIN_AT_OPENING = 20
"""A fine look is used only if it shows at least this many points over the estimated
opening and its rim (`points_at_opening`): behind a wall the camera sees the wall's back,
and OPN's offsets from such views moved the peg 10-100 mm away (development bodies); a view
of the opening shows hundreds."""
NEAR_VIEW = 0.15
"""`look_again`: an OAKN estimate made from further than FAR_VIEW is taken again from this
far from it (m), the peg aimed at it: from there the opening is within 15 deg of the image's
centre."""
FAR_VIEW = 0.2
"""From further than this (m), e.g. 30 cm, the opening can sit at the view's edge with part
of the body cut off."""
MAX_TURNS = 3
"""`look_again`: a fine look that sees nothing tries each of the other three yaws of a
square at most once ..."""
UNFITTED_LOOKS = 3
"""`look_again`: this many fine looks in a row that fitted no opening count as a look that
sees nothing round the peg: on the development bodies every episode with that pattern had
stopped on the rim, its estimate 7-40 mm off where the camera saw too little of the face."""
RISE = 0.02
"""... after looking once from this much further back than the pre-insertion pose (m): the
opening then 15 cm from the camera, beyond a D435's 12.7 cm minimum range."""


def weights_for(
    task: str,
    peg: str,
    weights_dir: Path,
    augmentation: bool | None = None,
    mount: str | None = None,
) -> dict[str, Path]:
    """The OAKN / OPN files for a task: `tasks.yaml` in the weights folder maps task names;
    tasks it does not list (e.g. new task files) use `<peg>/oakn.pt`, `<peg>/opnv.pt`.
    With `augmentation` set, the file trained that way: the shipped one if its .json says
    so, else its `_aug` / `_noaug` sibling. A file trained on the views of camera mount
    `mount`, `<name>.<mount>.pt` beside it, is taken in its place where there is one."""
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
        if mount and (own := p.with_name(f"{p.stem}.{mount}.pt")).is_file():
            p = own
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
        self.half = hole_half_extent(task.peg, task.clearance)  # the opening's nominal size
        self.round_opening = task.peg == "round"
        files = weights_for(
            task.name, task.peg, self.cfg.weights_dir, self.cfg.augmentation, task.mount.name
        )
        self.oakn, self.oakn_meta = load_weights(files["oakn"], "oakn", task.peg)
        self.opn, self.opn_meta = load_weights(files["opn"], ("opnv", "opn"), task.peg)
        # the coarse moves and the insertion, the fine loop, a step back and down, the turns
        self.max_decisions = 3 + self.cfg.max_fine_iterations + 2 + MAX_TURNS
        self.rng = np.random.default_rng(0)
        self.stage = "coarse"
        self.fine_steps = 0
        self.correction = IDENTITY
        self.peg_fix: np.ndarray | None = None

    def reset(self, seed: int) -> None:
        self.stage, self.fine_steps = "coarse", 0
        self.correction = IDENTITY  # the camera's errors change with the episode
        self.peg_fix = None
        self.sightings = Sightings()  # the fine looks' measurements of the hole
        self.blind_x: list[np.ndarray] = []  # tool x axes whose fine look saw nothing
        self.rise = 0.0  # how much further back than the pre-insertion pose it servoes
        self.unfitted = 0  # fine looks in a row that fitted no opening
        self.phase, self.estimate = "", None
        # How unsure the estimate is: not searched onto an opening (`on_face`), then the
        # spread of OAKN's candidates for it (`coarse_look`).
        self.doubt = (True, np.inf)
        # Point subsets are random; seeded per episode, so the same episode repeats exactly.
        self.rng = np.random.default_rng(seed)

    # ------------------------------------------------------------------ perception
    def estimate_hole(self, pts: np.ndarray, tcp: np.ndarray) -> np.ndarray | None:
        """OAKN + Algorithm 1: the hole's world frame from one wrist view's tool-frame object
        points `pts` (`object_points`), or None."""
        found = self.coarse_look(pts, tcp)
        return None if found is None else found[0]

    @torch.no_grad()
    def coarse_look(self, pts: np.ndarray, tcp: np.ndarray) -> tuple[np.ndarray, float] | None:
        """`estimate_hole` and the spread of OAKN's candidates for the opening (metres,
        `keypoint_spread`), or None."""
        if len(pts) < MIN_OBJECT_POINTS:
            return None
        x = torch.from_numpy(sample_fixed(pts, int(self.oakn_meta["points"]), self.rng))[None]
        offsets, logits = self.oakn(x)
        w = torch.sigmoid(logits) if self.cfg.confidence_map else None
        k, cand = weighted_keypoints(x, offsets, w)
        k_world = tool_to_world(k[0].numpy().astype(np.float64), tcp)
        H = L.hole_frame_from_keypoints(k_world.astype(np.float64))
        if not np.all(np.isfinite(H)):
            return None
        return H, float(keypoint_spread(cand, k, w)[0])

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

    def refine(self, a: np.ndarray, world: np.ndarray, tcp: np.ndarray) -> tuple[np.ndarray, str]:
        """OPN's offset `a` refined by the geometry of the face round the opening it points
        at (`world`: the fine view's object points): in 6-DoF the hole's axis from the
        face's normal (`rim_plane`; 3- and 4-DoF holes are upright), then the centre (and a
        square's yaw) from the opening seen on that face and its height from the face
        (`opening_fit`), fused with the looks before (sightings.py). Every look takes this
        path: where the 6-DoF ring shows no face, the look keeps OPN's axis and counts as
        OPN's measurement, so one far-off look does not undo the others. Returns the offset
        and where it came from."""
        T = L.apply_action(tcp, a)
        T = T if self.task.dof == 6 else self.constrain(T, tcp)
        H = L.hole_frame_from_pre_insertion(T)
        where, axis_seen = "upright axis", True
        if self.task.dof == 6:
            n = self.rim_axis(world, H)
            axis_seen = n is not None
            H, where = (align_axis(H, n), "axis from the rim") if axis_seen else (H, "OPN axis")
        if self.cfg.opening_fit:
            world = self.sightings.cloud(world)
            seen = locate_opening(world, H, self.half, round_opening=self.round_opening)
            where += ", OPN position" if seen is None else ", centre from the opening"
            H = H if seen is None else seen
            level, _ = face_height(world, H, self.half, round_opening=self.round_opening)
            if level is not None:
                H = H.copy()
                H[:3, 3] += level * H[:3, 2]
                where += ", height from the face"
            self.unfitted = 0 if seen is not None else self.unfitted + 1
            measured = seen is not None and axis_seen  # else as uncertain as OPN alone
            H = self.sightings.add(H, measured, float(np.linalg.norm(a[:3])))
            if len(self.sightings) > 1:
                where += f" (mean of {len(self.sightings)} looks)"
        pose = insertion_pose(self.peg, H, -PRE_INSERT_HEIGHT, T)
        return L.fine_action(tcp, pose), where

    def on_face(self, H: np.ndarray, world: np.ndarray) -> tuple[np.ndarray, bool]:
        """OAKN's hole frame `H` upright about its origin in 3- and 4-DoF (not about the
        pre-insertion pose, whose lever turns a tilt into a lateral error), then moved onto
        the opening the cloud `world` shows round it (`opening_fit`,
        perception/opening_search.py); and whether it was."""
        if self.task.dof != 6:
            H = H.copy()
            H[:3, :3] = G.frame_with_z(np.array([0.0, 0.0, 1.0]), H[:3, 0])
        if not self.cfg.opening_fit:
            return H, False
        if self.task.dof == 6 and (n := self.rim_axis(world, H)) is not None:
            H = align_axis(H, n)
        found = search_opening(world, H, self.half, round_opening=self.round_opening)
        return (H, False) if found is None else (found, True)

    def sees_opening(self, world: np.ndarray) -> bool:
        """Whether the fine view's object points `world` show the estimated opening and its
        rim (MIN_AT_OPENING); always, with no estimate."""
        if self.estimate is None:
            return True
        seen = points_at_opening(world, self.estimate, self.half, self.round_opening)
        return seen >= MIN_AT_OPENING

    def rim_axis(self, world: np.ndarray, H: np.ndarray) -> np.ndarray | None:
        """The hole's axis from the face round the opening of hole frame `H` (its normal,
        `rim_plane`), or None when the ring round the opening shows no face."""
        square_x = None if self.round_opening else H[:3, 0]  # the ring follows its sides
        return rim_normal(world, H[:3, 3], H[:3, 2], self.half, self.rng, square_x)

    def approach(self, H: np.ndarray, world: np.ndarray, tcp: np.ndarray) -> np.ndarray:
        """The pre-insertion pose over hole frame `H`: at the yaw nearest the tool's own or,
        with `clear_view`, the nearest whose camera sees the opening past what stands on
        the face (`world`: the coarse view's object points)."""
        nearest = self.standoff(H, tcp)
        if not (self.cfg.clear_view and not self.round_opening and self.task.dof != 3):
            return nearest  # a 3-DoF peg keeps its yaw (task_dof.constrain)
        poses = approach_yaws(nearest, tcp[:3, 0])
        i, _ = clear_view_yaw(world, poses, self.task.camera_in_tcp(), H)
        return poses[i]

    def nearer_view(self, H: np.ndarray, tcp: np.ndarray) -> Action | None:
        """`look_again`, coarse: OAKN's first estimate `H`, made from further than FAR_VIEW,
        is looked at again from NEAR_VIEW, on the line from it to the peg's tip and with
        the peg aimed at it; None to go on (near enough)."""
        away = tcp[:3, 3] - H[:3, 3]
        far = np.linalg.norm(away)
        if not self.cfg.look_again or far <= FAR_VIEW:
            return None
        R = G.frame_with_z(-away / far, tcp[:3, 0])
        view = G.make(R, H[:3, 3] + NEAR_VIEW * away / far)
        self.phase = f"coarse: estimate from {far * 100:.0f} cm, looking again from nearer"
        return Action.move(self.constrain(view, tcp))

    def look_again(self, tcp: np.ndarray, why: str = "nothing seen round the peg") -> Action | None:
        """`look_again`: a fine look saw nothing round the peg, or UNFITTED_LOOKS in a row
        fitted no opening (`why`, for the phase). First the current estimate's
        pre-insertion pose RISE further back (the opening beyond the camera's minimum
        range, over what stands near it), then, a square in 4/6-DoF, the least wrist turn
        whose yaw is at least 45 deg from every yaw that saw nothing; None when all are
        tried."""
        if not self.cfg.look_again or self.estimate is None:
            return None
        if self.rise == 0.0:
            self.rise = RISE
            self.phase = f"fine: {why}, looking again {RISE * 1000:.0f} mm back"
            return Action.move(self.constrain(self.standoff(self.estimate, tcp), tcp))
        if self.task.dof == 3:
            return None  # a 3-DoF peg keeps its yaw (task_dof.constrain)
        self.blind_x.append(tcp[:3, 0].copy())
        for pose in approach_yaws(self.standoff(self.estimate, tcp), tcp[:3, 0]):
            if all(pose[:3, 0] @ x < np.cos(np.radians(45)) for x in self.blind_x):
                self.phase = f"fine: {why}, the wrist turned"
                return Action.move(self.constrain(pose, tcp))
        return None

    def standoff(self, H: np.ndarray, tcp: np.ndarray) -> np.ndarray:
        """The pose the fine stage servoes to over hole frame `H`: the pre-insertion pose,
        `rise` further back once the camera saw nothing from there (`look_again`)."""
        return insertion_pose(self.peg, H, -PRE_INSERT_HEIGHT - self.rise, tcp)

    def constrain(self, T: np.ndarray, ref: np.ndarray) -> np.ndarray:
        return constrain(self.task, T, ref)

    def calibrated_points(self, xyzw: np.ndarray, tcp: np.ndarray) -> np.ndarray:
        """The cloud's world points that saw something, with the episode's `calibration`:
        the table's (measured on the coarse view, where most of the table is in sight),
        then moved onto the peg it shows (measured on the same view, where no part stands
        near the peg)."""
        world = valid_world_points(xyzw)
        if self.cfg.calibration:
            camera = tcp.copy()  # the tool's axes serve: the camera is fixed to the tool
            camera[:3, 3] = tcp[:3, :3] @ self.task.camera_in_tcp() + tcp[:3, 3]
            coarse = self.stage == "coarse"  # most of the table in sight, nothing near the peg
            if coarse:
                self.correction = correction_from_table(world, camera) or IDENTITY
            world = self.correction.apply(world.astype(np.float64), camera)
            if coarse:
                self.peg_fix = peg_correction(world, tcp, self.peg, self.task.peg_chamfer)
            world = apply_correction(self.peg_fix, world, tcp)
        return world

    # ------------------------------------------------------------------ decisions
    def act(self, observation: Observation) -> Action:
        tcp = observation.tcp_pose
        xyzw = observation.obs["pointcloud"]["xyzw"][0].cpu().numpy()
        if self.stage == "coarse":
            pts = world_object_points(self.calibrated_points(xyzw, tcp), tcp, self.peg)
            found = self.coarse_look(pts, tcp)
            first = self.estimate is None  # the coarse stage looks twice at most
            if found is None and first:
                return Action.give_up("OAKN: the camera sees no hole object")
            world = tool_to_world(pts, tcp)
            doubt = None
            if found is not None:
                H, on_opening = self.on_face(found[0], world)
                doubt = (not on_opening, found[1])
            # Of two looks, the one put on an opening it shows, then the one OAKN is surer
            # of: from nearer, walls beside the opening can fill the view and pull its
            # candidates apart.
            took = doubt is not None and (first or doubt < self.doubt)
            if took:
                self.estimate, self.doubt = H, doubt
            H = self.estimate
            if first and (view := self.nearer_view(H, tcp)) is not None:
                return view
            self.phase = "coarse: OAKN keypoints -> hole frame"
            if not took:  # the nearer look saw no object, or its candidates lay further apart
                self.phase += ", the first look's"
            self.stage = "fine" if self.cfg.coarse_to_fine else "insert"
            pose = self.approach(H, world, tcp)
            return Action.move(self.constrain(pose, tcp))
        if self.stage == "fine" and self.fine_steps < self.cfg.max_fine_iterations:
            pts = world_object_points(self.calibrated_points(xyzw, tcp), tcp, self.peg)
            world = tool_to_world(pts, tcp)
            a = self.predict_offset(fine_crop(pts)) if self.sees_opening(world) else None
            if a is None:
                again = self.look_again(tcp)
                if again is not None:
                    return again
                if self.estimate is None:
                    return Action.give_up("OPN: nothing seen around the peg")
                self.phase = "fine: no view shows the opening, inserting at the estimate"
                self.stage = "insert"
                return self.insert(tcp)
            source = "OPN offset"
            if self.cfg.rim_plane:
                a, source = self.refine(a, world, tcp)
                unfitted = f"no opening fitted in {UNFITTED_LOOKS} looks"
                if self.unfitted >= UNFITTED_LOOKS and (again := self.look_again(tcp, unfitted)):
                    self.unfitted = 0
                    return again
            # the remaining offset in the allowed DoF only
            pre = self.constrain(L.apply_action(tcp, a), tcp)  # the pre-insertion pose
            self.estimate = L.hole_frame_from_pre_insertion(pre)
            target = self.standoff(self.estimate, pre) if self.rise else pre
            a = L.fine_action(tcp, target)
            small = (
                np.linalg.norm(a[:3]) < self.cfg.tol_translation
                and np.degrees(np.linalg.norm(a[3:])) < self.cfg.tol_rotation_deg
            )
            if not small:
                self.fine_steps += 1
                self.phase = f"fine iteration {self.fine_steps}: {source}"
                return Action.move(target)
            if self.cfg.final_correction:
                self.stage = "insert"  # the next decision inserts, whatever it sees
                self.phase = f"final correction: the last {source} below (e_t, e_r)"
                return Action.move(target)
        self.phase = "insertion"
        return self.insert(tcp)

    def insert(self, tcp: np.ndarray) -> Action:
        """Insert; from further back than the pre-insertion pose (`look_again`), first move
        to it over the estimate (the insertion starts PRE_INSERT_HEIGHT from the opening)."""
        if self.rise and self.estimate is not None:
            self.rise, self.stage = 0.0, "insert"
            self.phase += ": first down to the pre-insertion pose"
            return Action.move(self.constrain(self.standoff(self.estimate, tcp), tcp))
        return Action.insert()
