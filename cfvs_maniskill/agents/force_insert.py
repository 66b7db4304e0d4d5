"""Force-guided insertion for tight fits: what a real assembly cell does with a wrist
force/torque sensor when the hole's play is below the arm's and the camera's accuracy.

The position-controlled insertion (`Executor.insert`, the paper's) pushes along the axis
the arm happens to be on. Below ~2 mm of clearance that fails even with the true hole pose:
the arm still lags its last move by 1-3 mm / 0.4 deg when the insertion starts (measured:
the oracle made 2/10 at 0.5 mm). Here instead, every control step:

* the insertion runs along the *commanded* pre-insertion pose, which the arm converges to;
* admittance: the commanded pose yields to the measured contact wrench (`env.peg_wrench`)
  - rotation about the tip by `rot_gain` x moment, lateral by `lat_gain` x force - so the
  hole's rim and walls turn and centre the peg (a remote-centre-compliance device emulated
  in software; on the rim the whole moment is used, which lays the peg's face flat on it,
  inside the hole only the walls' side pushes are);
* on the rim, a slow spiral search from the centre whose pitch is below what the peg can
  enter by (its chamfer + half the clearance), so no entry point is skipped;
* in the hole, a stall ends the insertion only after `stall_steps_in_hole` steps without
  progress: the compliance needs time to free a peg that sticks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

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
    max_steps: int = 1200
    """Give up after this many control steps (60 s)."""


def spiral_pitch(search_pitch: float, clearance: float, chamfer: float) -> float:
    """Spiral pitch no larger than the width of positions from which the peg drops in."""
    return min(search_pitch, chamfer + clearance / 2)


def force_insert(executor, depth: float, entry: float, start: np.ndarray, fcfg: ForceInsertConfig):
    """Insert `depth` m along the commanded tcp pose `start` (4x4, world) with admittance.

    Returns (steps taken, reason it ended: "" when the commanded depth was reached)."""
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
    in_hole = searched = False
    while cmd < depth:
        if executor.steps - steps0 >= fcfg.max_steps:
            return executor.steps - steps0, "insertion timed out"
        force, moment, side_moment = env.peg_wrench()
        w = fcfg.rot_gain * (side_moment if in_hole else moment)
        n = np.linalg.norm(w)
        if n > fcfg.max_rot_step:
            w *= fcfg.max_rot_step / n
        z_before = C[:3, 2].copy()
        C[:3, :3] = Rotation.from_rotvec(w).as_matrix() @ C[:3, :3]
        z = C[:3, 2]
        # Turn about the commanded tip, where the moment is taken: the line's zero-depth
        # point moves so the tip stays put (turning about it, 3 cm up, swung the tip
        # sideways into the wall and kept tilted pegs jammed at the entry).
        centre = centre + cmd * (z_before - z)
        done = float((env.tcp_matrix()[:3, 3] - origin) @ z)
        side = force - (force @ z) * z
        if spiral is None:
            d = fcfg.lat_gain * side
            n = np.linalg.norm(d)
            centre = centre + (d * fcfg.max_lat_step / n if n > fcfg.max_lat_step else d)
        elif done > spiral.stalled_at + fcfg.drop:
            centre, lateral, spiral, in_hole = centre + lateral, np.zeros(3), None, True
        else:
            offset = spiral.step(executor.dt)
            if offset is None:
                return executor.steps - steps0, "searched the whole spiral"
            lateral = C[:3, :3] @ offset
        cmd = min(depth, cmd + cfg.insert_speed * executor.dt, done + cfg.max_lead)
        T = C.copy()
        T[:3, 3] = centre + cmd * z + lateral
        q_prev = q
        q, ok = env.ik(T, q)
        if not ok:
            return executor.steps - steps0, "insertion path unreachable"
        executor._step(q, (q - q_prev) / executor.dt)
        now = float((env.tcp_matrix()[:3, 3] - origin) @ z)
        history.append(now)
        in_hole = in_hole or now > entry + 0.003
        if in_hole:
            k = fcfg.stall_steps_in_hole
        elif entry_zone[0] <= now <= entry_zone[1]:
            k = fcfg.stall_steps_at_entry
        else:
            k = cfg.stall_steps
        if spiral is None and stalled(history, k):
            if not in_hole and cfg.search_radius > 0 and not searched:
                spiral = SpiralSearch(
                    pitch, fcfg.search_speed, cfg.search_radius, now, min_radius=pitch / 4
                )
                searched = True
                continue
            break  # at the bottom, or stuck
    return executor.steps - steps0, ""
