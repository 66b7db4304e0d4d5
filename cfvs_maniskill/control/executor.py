"""The executor every agent shares: target tcp poses -> IK -> joint-position control steps.

Agents only decide *where* the peg should go; this module moves it there the same way for
all of them, so their success rates and servo times compare fairly.

* Moves are straight lines in Cartesian space (slerp in rotation) at most `max_speed`
  (0.5 m/s) and `max_turn` (90 deg/s): half the UR5's tool speed, near parts. Every
  waypoint is solved by IK (Pinocchio, seeded by the previous one); an unreachable target is
  reported, never silently held. A line that would touch what the camera has seen (or the
  table), or cannot be followed, is replaced by a planned joint path (planner.py).
* Servo time is simulated time: control steps x 0.05 s.
* `insert` moves the peg down its own axis with limited force: the commanded pose may lead
  the real tip by at most `max_lead` (4 mm), which with the arm's joint stiffness bounds the
  contact force to a few tens of newtons; a peg that stops advancing (on a rim) ends the
  insertion instead of being pushed through.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cfvs_maniskill import geometry as G
from cfvs_maniskill.constants import DEFAULT_SEARCH_RADIUS
from cfvs_maniskill.control.force_insert import ForceInsertConfig, force_insert
from cfvs_maniskill.control.planner import PathPlanner, PlannerConfig
from cfvs_maniskill.control.robot import Robot, SimRobot
from cfvs_maniskill.control.spiral import SpiralSearch, stalled


@dataclass
class MoveResult:
    ok: bool
    reason: str = ""
    steps: int = 0


@dataclass
class ExecutorConfig:
    max_speed: float = 0.5
    """Tool speed limit, m/s (half the UR5's 1 m/s; half of this gave the same success)."""
    max_turn: float = np.radians(90.0)
    """Tool rotation speed limit, rad/s."""
    settle_steps: int = 3
    """Extra control steps at the goal so the arm comes to rest (the velocity
    feed-forward leaves little lag; 6 measured no better)."""
    insert_speed: float = 0.1
    """Insertion speed along the tool axis, m/s."""
    max_lead: float = 0.004
    """How far the commanded tip may run ahead of the real one during insertion, m."""
    max_joint_step: float = 0.5
    """Largest joint change (rad) between waypoints 12.5 mm apart before we call it a flip."""
    reach_tolerance: float = 0.005
    """A move that ends further than this (m) from its target is reported as not reached."""
    stall_steps: int = 6
    """Insertion ends when the tip advanced < 0.5 mm over this many steps."""
    search_radius: float = DEFAULT_SEARCH_RADIUS
    """Compliant search (as real assembly cells do): when the peg stalls on the hole's rim,
    keep pressing lightly and slide it along a spiral of up to this radius (m) until it
    drops in. 0 = off (the paper's plain insertion)."""
    search_pitch: float = 0.0012
    """Distance between the spiral's turns, m (below the clearance, so no gap is skipped)."""
    search_speed: float = 0.02
    """Sliding speed along the spiral, m/s."""
    search_drop: float = 0.003
    """The spiral stops once the peg has dropped this far (m) below where it stalled: it is
    in the opening; straight down from there."""
    rim_band: float = 0.005
    """A stall short of the expected entry + this (m) means the peg sits on the rim (which
    starts the search); deeper, it is at the bottom or stuck."""
    insertion: str = "auto"
    """position: the paper's insertion along the arm's current axis; force: force-guided
    insertion with admittance (`force_insert`); auto: force below `force_below_clearance`."""
    force_below_clearance: float = 0.002
    """auto picks the force-guided insertion for holes with less clearance than this, m
    (the paper's 4 mm tasks keep the insertion their results were measured with)."""
    force: ForceInsertConfig = field(default_factory=ForceInsertConfig)
    plan: bool = True
    """Plan a collision-free joint path (control/planner.py) when a move's straight line
    would touch what the camera has seen or the table, or cannot be followed. False: the
    paper's straight lines only."""
    joint_speed: float = 0.5
    """Joint speed along planned paths, rad/s: slow enough that the arm's lag behind the
    path stays inside the planner's margin."""
    planner: PlannerConfig = field(default_factory=PlannerConfig)


def _gap(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """How far tcp pose b is from a: distance (m) and turn (rad)."""
    return float(np.linalg.norm(b[:3, 3] - a[:3, 3])), G.rot_angle(a[:3, :3].T @ b[:3, :3])


class Executor:
    def __init__(self, robot: Robot | Any, cfg: ExecutorConfig | None = None):
        """`robot`: a Robot, or a PegInsertEnv (or its gym wrapper) to drive as one."""
        self.robot: Robot = robot if isinstance(robot, Robot) else SimRobot(robot)
        self.cfg = cfg or ExecutorConfig()
        self.dt = self.robot.dt
        self.steps = 0
        self.planned_moves = 0
        """Moves this episode that followed a planned path instead of the straight line."""
        self.planner = None
        if self.cfg.plan:
            self.planner = PathPlanner(
                self.robot.collision, self.robot.ik, self.robot.joint_limits, self.cfg.planner
            )
        self.last_obs = None
        self.last_target: np.ndarray | None = None
        """The last pose `move_to` commanded (where the arm is converging to)."""
        self.phase = ""
        """What the insertion is doing (for videos' captions): set by `insert`."""
        self.on_step: Callable[[Executor], None] | None = None
        """Called after every control step (a video films from it); None: nothing."""
        if self.cfg.insertion not in ("auto", "position", "force"):
            raise ValueError(
                f"ExecutorConfig.insertion: expected auto | position | force, "
                f"got {self.cfg.insertion!r}"
            )

    @property
    def servo_time(self) -> float:
        """Simulated seconds spent moving since the last `reset`."""
        return self.steps * self.dt

    def reset(self, obs=None) -> None:
        """A new episode; `obs`: its first observation (what the camera sees at the start)."""
        self.steps = 0
        self.planned_moves = 0
        self.last_target = None
        self.phase = ""
        if self.planner is not None:
            self.planner.forget()
            if obs is not None:
                self._note(obs)

    @property
    def insertion_mode(self) -> str:
        if self.cfg.insertion != "auto":
            return self.cfg.insertion
        return "force" if self.robot.clearance < self.cfg.force_below_clearance else "position"

    def step_towards(self, T: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, bool]:
        """One insertion control step: IK for the tcp pose T from joint angles q, then a
        step there with the velocity that gets there in one step. (joint angles, False)
        when T has no IK solution (nothing is stepped)."""
        q_new, ok = self.robot.ik(T, q)
        if ok:
            self._step(q_new, (q_new - q) / self.dt)
        return q_new, ok

    def _step(self, q: np.ndarray, qd: np.ndarray | None = None):
        """One control step towards joint positions q with joint velocities qd (rad/s)."""
        self.robot.command(q, qd)
        self.steps += 1
        if self.on_step is not None:
            self.on_step(self)

    def move_to(self, target: np.ndarray) -> MoveResult:
        """Move the tcp to world pose `target` (4x4): along a straight line, or along a
        planned collision-free joint path when the line would touch what the camera has
        seen (or the table) or cannot be followed."""
        if target.shape != (4, 4) or not np.all(np.isfinite(target)):
            return MoveResult(False, "target pose is not a finite 4x4 matrix")
        q0, start = self.robot.joints(), self.robot.tcp()
        dist, turn = _gap(start, target)
        path, reason = self._straight_path(start, target, q0, dist, turn)
        small = dist < self.cfg.planner.small_move and turn < np.radians(5.0)
        # Small moves near the part are the agent's to make: never planned.
        if self.planner is not None and (
            path is None or (not small and not self.planner.path_free([q0, *path]))
        ):
            planned = self.planner.plan(q0, target)
            if planned is not None:
                path = self._timed(planned)
                self.planned_moves += 1
        if path is None:
            return MoveResult(False, reason)
        steps0 = self.steps
        self.last_target = target.copy()
        prev = q0
        for q in path:
            self._step(q, (q - prev) / self.dt)
            prev = q
        for _ in range(self.cfg.settle_steps):
            self._step(path[-1])
        self._look()  # one observation, where the agent looks next
        err, err_rot = _gap(self.robot.tcp(), target)
        err_rot = np.degrees(err_rot)
        if err > self.cfg.reach_tolerance or err_rot > 3.0:
            return MoveResult(
                False,
                f"target not reached: {1000 * err:.1f} mm, {err_rot:.1f} deg off (blocked by contact?)",
                self.steps - steps0,
            )
        return MoveResult(True, "", self.steps - steps0)

    def _straight_path(
        self, start: np.ndarray, target: np.ndarray, q: np.ndarray, dist: float, turn: float
    ) -> tuple[list | None, str]:
        """Joint waypoints (from joints q) of the straight Cartesian line from tcp pose
        `start` to `target`, `dist` m and `turn` rad apart, at the speed limits (one per
        control step), or None and why it cannot be followed."""
        n = max(1, int(np.ceil(max(dist / self.cfg.max_speed, turn / self.cfg.max_turn) / self.dt)))
        _, ok = self.robot.ik(target, q)
        if not ok:
            return None, "target pose unreachable (no IK solution)"
        path = []
        line = G.interpolator(start, target)
        for i in range(1, n + 1):
            q_prev = q
            q, ok = self.robot.ik(line(i / n), q)
            if not ok:
                return None, f"path unreachable at {i}/{n} of the way (no IK solution)"
            if np.abs(q - q_prev).max() > self.cfg.max_joint_step:
                # IK jumped to another arm configuration: the straight line is not followable.
                return None, f"path needs an arm configuration flip at {i}/{n}"
            path.append(q)
        return path, ""

    def _timed(self, path: list[np.ndarray]) -> list[np.ndarray]:
        """A planned path's joint waypoints, one per control step at `joint_speed`."""
        out = []
        step = self.cfg.joint_speed * self.dt
        for a, b in zip(path[:-1], path[1:], strict=True):
            n = max(1, int(np.ceil(np.abs(b - a).max() / step)))
            out += [a + (b - a) * i / n for i in range(1, n + 1)]
        return out

    def _look(self) -> None:
        """Observe, and add what the camera saw to the planner's known world."""
        self.last_obs = self.robot.observe()
        if self.planner is not None:
            self._note(self.last_obs)

    def know(self, points: np.ndarray) -> None:
        """Obstacle points (world frame) the planner avoids this episode, besides what the
        camera sees: a cell's CAD model of the fixture, or the oracle's true object."""
        if self.planner is not None:
            self.planner.know(points)

    def _note(self, obs) -> None:
        """Hand the planner an observation taken where the arm is now."""
        r = self.robot
        self.planner.observe(obs, r.joints(), r.tcp(), r.peg)

    def insert(self, depth: float, entry: float = 0.0) -> MoveResult:
        """Push the peg `depth` metres along its own axis (its +z), with bounded force.

        `entry` is the travel at which the tip should pass the hole's opening; a stall
        before entry + 5 mm means the peg sits on the rim, which starts the spiral search
        when `search_radius` > 0.
        """
        if self.insertion_mode == "force":
            start = self.robot.tcp() if self.last_target is None else self.last_target
            steps, outcome = force_insert(self, depth, entry, start, self.cfg.force)
            q = self.robot.joints()
            for _ in range(self.cfg.settle_steps):
                self._step(q)
            ok = outcome.peg_is_in_place  # the score says where it is
            return MoveResult(ok, "" if ok else outcome.reason, steps + self.cfg.settle_steps)
        T0 = self.robot.tcp()
        axis = T0[:3, 2]
        q = self.robot.joints()
        cmd = 0.0
        history = [0.0]
        steps0 = self.steps
        lateral = np.zeros(3)
        spiral: SpiralSearch | None = None  # search state once started
        while cmd < depth:
            self.phase = "insertion" if spiral is None else "search: spiral on the rim"
            done = float((self.robot.tcp()[:3, 3] - T0[:3, 3]) @ axis)
            cmd = min(depth, cmd + self.cfg.insert_speed * self.dt, done + self.cfg.max_lead)
            if spiral is not None:
                if done > spiral.stalled_at + self.cfg.search_drop:
                    spiral = None  # dropped into the hole: straight down from here
                else:
                    offset = spiral.step(self.dt)
                    if offset is None:
                        break  # searched the whole disc: give up on this insertion
                    lateral = T0[:3, :3] @ offset
            T = T0.copy()
            T[:3, 3] = T0[:3, 3] + cmd * axis + lateral
            q, ok = self.step_towards(T, q)
            if not ok:
                return MoveResult(False, "insertion path unreachable", self.steps - steps0)
            history.append(float((self.robot.tcp()[:3, 3] - T0[:3, 3]) @ axis))
            if spiral is None and stalled(history, self.cfg.stall_steps):
                on_rim = history[-1] < entry + self.cfg.rim_band
                if on_rim and self.cfg.search_radius > 0 and not np.any(lateral):
                    c = self.cfg
                    spiral = SpiralSearch(
                        c.search_pitch, c.search_speed, c.search_radius, history[-1]
                    )
                    continue
                break  # blocked: on the rim or at the bottom
        for _ in range(self.cfg.settle_steps):
            self._step(q)
        return MoveResult(True, "", self.steps - steps0)
