"""Force-guided insertion for tight fits: what a real assembly cell does with a wrist
force/torque sensor when the hole's play is below the arm's and the camera's accuracy
(docs/tight-fits.md has the measurements behind each choice). Every control step:

* the insertion runs along the *commanded* pre-insertion pose, which the arm converges to
  (pushing along the arm's actual axis leaves its 1-3 mm lag in the hole);
* admittance: the commanded pose yields to the tared wrist wrench, moved to the tip -
  rotation about the tip by `rot_gain` x moment, lateral by `lat_gain` x side force - so
  the rim and walls turn and centre the peg (a remote-centre-compliance device in software);
* on the rim, a slow spiral from the centre with a pitch below what the peg can enter by,
  the turn bounded by `max_rim_correction` so a peg partly over the opening stays square;
* passing the rim, the peg keeps yielding to the whole moment within `max_correction`; a
  stall there takes it back to its start orientation to search as on the rim;
* a stall short of the hole first backs off and pushes again (PhysX at times stops a
  centred peg on phantom contacts as its chamfer passes the entry);
* in the hole, a stall ends the insertion only after `stall_steps_in_hole` steps: the
  compliance needs time to free a peg that sticks.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from cfvs_maniskill import geometry as G
from cfvs_maniskill.control.spiral import SpiralSearch, stalled
from cfvs_maniskill.robots.poses import flange_pose


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
    moves on; counted from the touch, not the estimated entry, whose height can be 1-2 mm
    off. A peg that drops off the spiral enters that phase too."""
    max_correction: float = np.radians(3.0)
    """Largest turn of the commanded pose away from the start pose once passing the rim or
    in the hole, rad: above the fine stage's tilt error, and a bound for a peg still on the
    rim but taken to be passing it, which would turn towards its load without end."""
    max_rim_correction: float = np.radians(1.0)
    """The same bound while the tip is on the rim (and searching there), rad: enough to lay
    the face flat on it, little enough that a peg resting partly over the opening does not
    tilt towards it while the spiral drags it. It bounds the whole turn, yaw included."""
    contact_force: float = 1.0
    """A tared reading above this (N) is the first touch (well above the sensor noise of
    the shipped profiles: 0.1 N per axis)."""
    max_steps: int = 1200
    """Give up after this many control steps (60 s)."""
    repush: int = 2
    """Times a peg that stalls short of the hole backs off and pushes again before the
    spiral search starts. In the 0.5 mm task PhysX at times makes contacts on the plane of
    the peg's chamfer, extended, where it meets the hole's corners 1.75 mm into the entry,
    while the walls are 0.25 mm away: a centred peg stops there (oracle, true pose: 3 of 60
    scenes), and the spiral then dragged it out. Pushed again, all 100 of seeds 100-199 go in."""
    back_off: float = 0.001
    """How far the commanded depth goes back for a re-push, m ..."""
    back_off_steps: int = 4
    """... held there this many control steps, so the arm lifts the peg before pushing."""
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
    robot, cfg = executor.robot, executor.cfg
    pitch = spiral_pitch(cfg.search_pitch, robot.clearance, robot.chamfer)
    entry_zone = (entry - fcfg.entry_margin, entry + robot.chamfer + fcfg.entry_margin)
    C = start.copy()
    origin = start[:3, 3].copy()
    centre = origin.copy()  # the insertion line's point at zero depth (moves with admittance)
    q = robot.joints()
    cmd, history, steps0 = 0.0, [0.0], executor.steps
    spiral: SpiralSearch | None = None
    lateral = np.zeros(3)
    phase = Phase.RIM
    searched = False
    contact_at: float | None = None  # travel at the first touch
    repushes, hold = 0, 0
    robot.tare()  # the peg is clear of the part here: this reading is the sensor's offset
    while cmd < depth:
        executor.phase = (
            f"insertion (force): {phase.value}" if spiral is None else "search: spiral on the rim"
        )
        if executor.steps - steps0 >= fcfg.max_steps:
            return executor.steps - steps0, Outcome.TIMED_OUT
        tcp = robot.tcp()  # forward kinematics
        flange = flange_pose(tcp)  # the peg's nominal length back along the axis
        force, moment = tip_wrench(robot.wrench(), flange, tcp[:3, 3])
        if contact_at is None and np.linalg.norm(force) > fcfg.contact_force:
            contact_at = history[-1]
        w = fcfg.rot_gain * moment  # yield to the whole moment, in every phase
        n = np.linalg.norm(w)
        if n > fcfg.max_rot_step:
            w *= fcfg.max_rot_step / n
        R = Rotation.from_rotvec(w).as_matrix() @ C[:3, :3]
        bound = fcfg.max_rim_correction if phase is Phase.RIM else fcfg.max_correction
        if G.rot_angle(start[:3, :3].T @ R) <= bound:
            centre = _turn_about_tip(C, centre, cmd, R)
        z = C[:3, 2]
        done = float((robot.tcp()[:3, 3] - origin) @ z)
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
        if hold > 0:  # backing off: the commanded depth stays put while the arm follows
            hold -= 1
        else:
            cmd = min(depth, cmd + cfg.insert_speed * executor.dt, done + cfg.max_lead)
        T = C.copy()
        T[:3, 3] = centre + cmd * z + lateral
        q, ok = executor.step_towards(T, q)
        if not ok:
            return executor.steps - steps0, Outcome.UNREACHABLE
        now = float((robot.tcp()[:3, 3] - origin) @ z)
        history.append(now)
        phase = next_phase(phase, now, entry, robot.chamfer, contact_at, searched, fcfg)
        k = stall_window(phase, now, entry_zone, fcfg, cfg)
        if spiral is None and stalled(history, k):
            if phase is not Phase.HOLE and repushes < fcfg.repush:
                repushes += 1
                cmd, hold, history = max(0.0, now - fcfg.back_off), fcfg.back_off_steps, [now]
                continue
            if phase is not Phase.HOLE and cfg.search_radius > 0 and not searched:
                # Short of the hole: on the rim, or a peg that slid off its edge into the
                # chamfer and wedged there. Back to the start orientation (the travel is
                # measured along the new axis), lay the face on the rim and search.
                centre = _turn_about_tip(C, centre, cmd, start[:3, :3])
                now = float((robot.tcp()[:3, 3] - origin) @ C[:3, 2])
                phase = Phase.RIM
                spiral = SpiralSearch(
                    pitch, fcfg.search_speed, cfg.search_radius, now, min_radius=pitch / 4
                )
                searched = True
                continue
            break  # at the bottom, or stuck
    return executor.steps - steps0, Outcome.ENDED
