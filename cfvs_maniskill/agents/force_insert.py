"""Force-guided insertion for tight fits: what a real assembly cell does with a wrist
force/torque sensor when the hole's play is below the arm's and the camera's accuracy.

The position-controlled insertion (`Executor.insert`, the paper's) pushes along the axis
the arm happens to be on. Below ~2 mm of clearance that fails even with the true hole pose:
the arm still lags its last move by 1-3 mm / 0.4 deg when the insertion starts (measured:
the oracle made 2/10 at 0.5 mm). Here instead, every control step:

* the insertion runs along the *commanded* pre-insertion pose, which the arm converges to;
* admittance: the commanded pose yields to the wrist force/torque sensor's reading
  (`env.wrist_wrench`, one 6-axis wrench at the flange, moved to the tip with the peg's
  nominal length) - rotation about the tip by `rot_gain` x moment, lateral by `lat_gain` x
  force - so the hole's rim and walls turn and centre the peg (a remote-centre-compliance
  device emulated in software; on the rim this lays the peg's face flat on it);
* on the rim, a slow spiral search from the centre whose pitch is below what the peg can
  enter by (its chamfer + half the clearance), so no entry point is skipped; there the
  commanded pose turns at most 1 deg from the start (enough to lay the face flat), so a
  peg resting partly over the opening does not tilt towards it while it searches;
* passing the rim (the tip in the opening, the full section reaching the rim's edge): a
  tilted peg's low side slides in against the wall while its high side's chamfer rests on
  the opposite edge. With contact forces split per contact (which no sensor measures) the
  pose turned *against* the axial load's moment there and straightened such pegs; with
  the one wrench a wrist sensor gives, yielding to the whole moment in this phase too is
  what works (measured on the same 160 tight-fit episodes: turning against the whole
  moment 42/80 at 0.5 mm and 69/80 at 1 mm, yielding to it 68/80 and 77/80). The phase
  starts 1 mm past the first touch (a peg on the flat rim stops where it touches, the
  estimated entry height can be 1-2 mm off), the turn stays within 3 deg of the start
  pose, and a peg that stalls in it goes back to its start orientation and searches as
  on the rim;
* in the hole, a stall ends the insertion only after `stall_steps_in_hole` steps without
  progress: the compliance needs time to free a peg that sticks.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from cfvs_maniskill import geometry as G
from cfvs_maniskill.agents.interface import flange_pose
from cfvs_maniskill.agents.spiral import SpiralSearch, stalled


@dataclass
class ForceInsertConfig:
    rot_gain: float = 0.003
    """Admittance in rotation: rad per control step per N m of moment about the tip."""
    lat_gain: float = 2e-5
    """Admittance across the axis: m per control step per N of side force."""
    max_rot_step: float = np.radians(0.5)
    """Largest turn of the commanded pose per control step, rad."""
    max_lat_step: float = 0.0003
    """Largest side shift of the commanded pose per control step, m."""
    drop: float = 0.001
    """The spiral stops when the peg has dropped this far below where it stalled, m."""
    stall_steps_in_hole: int = 40
    """Control steps without 0.5 mm of progress before a peg inside the hole counts as
    stuck (2 s at 20 Hz)."""
    entry_margin: float = 0.004
    """The entry zone, where a stall waits `stall_steps_at_entry`, reaches this far (m) above the
    entry and below the end of the chamfer (covers the error of the hole's estimate)."""
    search_speed: float = 0.008
    """Sliding speed along the spiral, m/s: slow enough (0.4 mm per control step) that the
    peg drops in where it passes over the lead-in instead of sliding across it and out."""
    stall_steps_at_entry: int = 12
    """Control steps without 0.5 mm of progress in the entry zone before the spiral search
    starts: a peg turning into the chamfer advances slowly, and a spiral started then drags
    it back out onto the rim."""
    passing_from: float = 0.001
    """Travel past the first touch (m) from which the tip counts as in the opening (the
    rim-passing phase): a peg on the flat rim stops where it touches, one in the chamfer
    moves on. A peg that drops off the spiral enters that phase too. (Counted from the
    estimated entry instead, a 1-2 mm error in the hole's height sent pegs on the rim into
    it: measured, 1 mm success 0.915 / 0.900 -> 0.880 / 0.845.)"""
    max_correction: float = np.radians(3.0)
    """Largest turn of the commanded pose away from the start pose once passing the rim or
    in the hole, rad (set when the fine stage left 2.2 deg of tilt at p90; a peg still on
    the rim but taken to be passing it turns towards its load without end otherwise:
    measured, 10-45 deg tilts)."""
    max_rim_correction: float = np.radians(1.0)
    """The same bound while the tip is on the rim (and searching there), rad. Enough to lay
    the face flat on it (the fine stage leaves 0.27 / 0.57 deg of tilt at p90, ideal /
    realistic); more let a peg resting partly over the opening tilt towards it while the
    spiral dragged it about, and it reached the opening 3.6 deg askew and jammed 3 mm in
    (most 0.5 mm failures under `realistic`, where the hand-eye error leaves 2 mm to
    search). It counts the whole turn, yaw included, so a peg arriving over 1 deg off in
    yaw cannot square itself on the rim (traced with OPN's yaw, `cfvs_no_opening`);
    bounding the tilt alone is the next change (docs/tight-fits.md)."""
    contact_force: float = 1.0
    """A tared reading above this (N) is the first touch (well above the sensor noise of
    the shipped profiles: 0.1 N per axis)."""
    max_steps: int = 1200
    """Give up after this many control steps (60 s)."""
    in_hole_past_chamfer: float = 0.003
    """Travel past the end of the chamfer (m) from which the peg's full section is in the
    hole (the `HOLE` phase)."""


class Phase(enum.Enum):
    """Where the peg is, as the wrist wrench and the travel tell it (module doc)."""

    RIM = "rim"
    """Not in the opening yet: on the flat rim, or short of it."""
    PASSING = "passing the rim"
    """The tip in the opening, the full section reaching the rim's edge."""
    HOLE = "in the hole"
    """The full section past the rim."""


class Outcome(enum.Enum):
    """How a force-guided insertion ended; `reason` is what the episode records."""

    ENDED = ""
    """The commanded depth was reached, or the peg stopped where it is (at the bottom, or
    stuck): the task's score says which."""
    SPIRAL_EXHAUSTED = "searched the whole spiral"
    TIMED_OUT = "insertion timed out"
    UNREACHABLE = "insertion path unreachable"

    @property
    def reason(self) -> str:
        return self.value

    @property
    def peg_is_in_place(self) -> bool:
        """The insertion itself did not fail: where the peg ended is for the score to say."""
        return self in (Outcome.ENDED, Outcome.SPIRAL_EXHAUSTED)


def next_phase(
    phase: Phase,
    travel: float,
    entry: float,
    chamfer: float,
    contact_at: float | None,
    searched: bool,
    fcfg: ForceInsertConfig,
) -> Phase:
    """The phase after a control step that left the tip `travel` m along the insertion
    line (`entry`: where the opening should be; `contact_at`: travel at the first touch)."""
    if travel > entry + chamfer + fcfg.in_hole_past_chamfer:
        return Phase.HOLE
    if (
        phase is Phase.RIM
        and not searched
        and contact_at is not None
        and travel > contact_at + fcfg.passing_from
    ):
        return Phase.PASSING
    return phase


def stall_window(phase: Phase, travel: float, entry_zone: tuple[float, float], fcfg, cfg) -> int:
    """Control steps without progress that count as a stall in this phase and place."""
    if phase is not Phase.RIM:
        return fcfg.stall_steps_in_hole
    if entry_zone[0] <= travel <= entry_zone[1]:
        return fcfg.stall_steps_at_entry
    return cfg.stall_steps


def spiral_pitch(search_pitch: float, clearance: float, chamfer: float) -> float:
    """Spiral pitch no larger than the width of positions from which the peg drops in."""
    return min(search_pitch, chamfer + clearance / 2)


def admittance_moment(phase: Phase, moment: np.ndarray) -> np.ndarray:
    """The moment (world, about the tip) the commanded pose turns along with: all of the
    measured one, in every phase (see the module doc for why not against it while passing
    the rim). `phase` is kept for the stall windows and the turn limit, which differ."""
    return moment


def tip_wrench(wrench: np.ndarray, flange: np.ndarray, tip: np.ndarray):
    """A flange-frame wrist wrench (fx fy fz tx ty tz, about the flange) -> the world-frame
    force and its moment about the peg tip."""
    R = flange[:3, :3]
    force, moment = R @ wrench[:3], R @ wrench[3:]
    return force, moment + np.cross(flange[:3, 3] - tip, force)


def _turn_about_tip(C: np.ndarray, centre: np.ndarray, cmd: float, R: np.ndarray) -> np.ndarray:
    """Give the commanded pose C (4x4, changed in place) the rotation R about its tip, which
    sits `cmd` along the axis from the insertion line's zero-depth point `centre`; returns
    the moved `centre`. Turning about the tip, where the moment is taken, keeps the tip put
    (turning about the line's start, 3 cm up, swung the tip sideways into the wall and kept
    tilted pegs jammed at the entry)."""
    z_before = C[:3, 2].copy()
    C[:3, :3] = R
    return centre + cmd * (z_before - C[:3, 2])


def force_insert(
    executor, depth: float, entry: float, start: np.ndarray, fcfg: ForceInsertConfig
) -> tuple[int, Outcome]:
    """Insert `depth` m along the commanded tcp pose `start` (4x4, world) with admittance.

    Returns (control steps taken, how it ended)."""
    env, cfg = executor.env, executor.cfg
    task = env.task
    pitch = spiral_pitch(cfg.search_pitch, task.clearance, task.peg_chamfer)
    entry_zone = (entry - fcfg.entry_margin, entry + task.peg_chamfer + fcfg.entry_margin)
    C = start.copy()
    origin = start[:3, 3].copy()
    centre = origin.copy()  # the insertion line's point at zero depth (moves with admittance)
    q = env.agent.robot.get_qpos()[0].cpu().numpy()
    cmd, history, steps0 = 0.0, [0.0], executor.steps
    spiral: SpiralSearch | None = None
    lateral = np.zeros(3)
    phase = Phase.RIM
    searched = False
    contact_at: float | None = None  # travel at the first touch
    # Tare: the peg is clear of the part here, so this reading is the sensor's offset.
    tare = env.wrist_wrench()
    while cmd < depth:
        executor.phase = (
            f"insertion (force): {phase.value}" if spiral is None else "search: spiral on the rim"
        )
        if executor.steps - steps0 >= fcfg.max_steps:
            return executor.steps - steps0, Outcome.TIMED_OUT
        tcp = env.tcp_matrix()  # forward kinematics
        flange = flange_pose(tcp)  # the peg's nominal length back along the axis
        force, moment = tip_wrench(env.wrist_wrench() - tare, flange, tcp[:3, 3])
        if contact_at is None and np.linalg.norm(force) > fcfg.contact_force:
            contact_at = history[-1]
        w = fcfg.rot_gain * admittance_moment(phase, moment)
        n = np.linalg.norm(w)
        if n > fcfg.max_rot_step:
            w *= fcfg.max_rot_step / n
        R = Rotation.from_rotvec(w).as_matrix() @ C[:3, :3]
        bound = fcfg.max_rim_correction if phase is Phase.RIM else fcfg.max_correction
        if G.rot_angle(start[:3, :3].T @ R) <= bound:
            centre = _turn_about_tip(C, centre, cmd, R)
        z = C[:3, 2]
        done = float((env.tcp_matrix()[:3, 3] - origin) @ z)
        side = force - (force @ z) * z
        if spiral is None:
            d = fcfg.lat_gain * side
            n = np.linalg.norm(d)
            centre = centre + (d * fcfg.max_lat_step / n if n > fcfg.max_lat_step else d)
        elif done > spiral.stalled_at + fcfg.drop:
            centre, lateral, spiral = centre + lateral, np.zeros(3), None
            phase = Phase.PASSING  # dropped into the opening
        else:
            offset = spiral.step(executor.dt)
            if offset is None:
                return executor.steps - steps0, Outcome.SPIRAL_EXHAUSTED
            lateral = C[:3, :3] @ offset
        cmd = min(depth, cmd + cfg.insert_speed * executor.dt, done + cfg.max_lead)
        T = C.copy()
        T[:3, 3] = centre + cmd * z + lateral
        q, ok = executor.step_towards(T, q)
        if not ok:
            return executor.steps - steps0, Outcome.UNREACHABLE
        now = float((env.tcp_matrix()[:3, 3] - origin) @ z)
        history.append(now)
        phase = next_phase(phase, now, entry, task.peg_chamfer, contact_at, searched, fcfg)
        k = stall_window(phase, now, entry_zone, fcfg, cfg)
        if spiral is None and stalled(history, k):
            if phase is not Phase.HOLE and cfg.search_radius > 0 and not searched:
                # Short of the hole: on the rim, or a peg that slid off its edge into the
                # chamfer and wedged there. Back to the start orientation (the travel is
                # measured along the new axis), lay the face on the rim and search.
                centre = _turn_about_tip(C, centre, cmd, start[:3, :3])
                now = float((env.tcp_matrix()[:3, 3] - origin) @ C[:3, 2])
                phase = Phase.RIM
                spiral = SpiralSearch(
                    pitch, fcfg.search_speed, cfg.search_radius, now, min_radius=pitch / 4
                )
                searched = True
                continue
            break  # at the bottom, or stuck
    return executor.steps - steps0, Outcome.ENDED
