"""One episode of any agent through the shared executor, as one result record."""

from __future__ import annotations

import hashlib
import math
import time
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from cfvs_maniskill import provenance
from cfvs_maniskill.constants import (
    INSERT_OVERSHOOT,
    PRE_INSERT_HEIGHT,
    SUCCESS_TIP_TOLERANCE,
    SUCCESS_WALL_PENETRATION,
)
from cfvs_maniskill.control.executor import Executor
from cfvs_maniskill.envs.scene import success_tilt_deg
from cfvs_maniskill.policies.base import Agent, AgentFailure, Observation, checked_action
from cfvs_maniskill.policies.interface import robot_view

if TYPE_CHECKING:
    from cfvs_maniskill.rendering.film import Film


@dataclass
class EpisodeResult:
    task: str
    agent: str
    object: str
    seed: int
    init_error_m: float
    success: bool
    servo_time_s: float
    steps: int
    reason: str
    tilt_deg: float
    """The hole's tilt from the vertical (the scene), deg."""
    tip_to_bottom_m: float
    lateral_offset_m: float
    wall_time_s: float
    sensor: str
    """The sensor profile the episode ran under ..."""
    mount: str
    """... and the wrist camera's mount on the tool (its `mount`, robots/mounts.py)."""
    provenance: dict = field(default_factory=dict)
    """Which code, weights, sensor profile, task and object files made it (provenance.py)."""
    move_residuals: list = field(default_factory=list)
    """After each of the agent's moves, the true error from the pre-insertion pose:
    [lateral mm, tilt deg] (measured by the runner from true poses; agents never see it)."""
    planned_moves: int = 0
    """Moves that followed a planned collision-free path instead of the straight line."""
    peg_tilt_deg: float = float("nan")
    """Where the peg ended: its axis from the hole's, deg ..."""
    wall_penetration_m: float | None = None
    """... and how far its section reached past the hole's wall (negative: play left; None:
    no full section below the opening), the success test's inputs (scene.score)."""
    decisions: list = field(default_factory=list)
    """The agent's account of each decision, in order (its `phase`, else the action's kind):
    which stage moved the peg and why, e.g. a second look from nearer."""
    agent_error: dict | None = None
    """What the agent did wrong, when the episode ended on it (AgentFailure.to_json)."""

    def to_json(self) -> dict:
        return asdict(self)


AGENT_SEED_SALT = b"cfvs_maniskill agent seed v1"


def agent_seed(episode_seed: int) -> int:
    """The seed an agent is reset with: a salted hash of the episode's seed. The env's own
    seed fixes the scene and the mount error, so an agent handed it could replay them."""
    digest = hashlib.blake2b(str(episode_seed).encode(), digest_size=8, key=AGENT_SEED_SALT)
    return int.from_bytes(digest.digest(), "little") & 0x7FFFFFFF


def failure_reason(m: dict, tilt_limit_deg: float) -> str:
    """Why a finished insertion is not a success, from the env's evaluate() metrics and the
    task's tilt limit (scene.success_tilt_deg)."""
    deep = m["tip_depth"] >= 0.005
    if m["tilt_error_deg"] > (tilt_limit_deg if deep else max(tilt_limit_deg, 10.0)):
        return f"peg tilted {m['tilt_error_deg']:.1f} deg from the hole axis"
    if not deep:
        if m["tip_depth"] > 0.001 and m["lateral_offset"] < 0.003:
            # In the opening, not on the rim: the full section did not follow (tilt, yaw).
            return f"peg stuck {1000 * m['tip_depth']:.1f} mm into the hole's entry"
        if m["lateral_offset"] < 0.06:
            return f"peg stopped on the rim ({1000 * m['lateral_offset']:.1f} mm off the axis)"
        return f"peg missed the hole ({1000 * m['lateral_offset']:.0f} mm off the axis)"
    if m["tip_to_bottom"] <= SUCCESS_TIP_TOLERANCE:
        if m["lateral_offset"] < 0.003 and m["wall_penetration"] > SUCCESS_WALL_PENETRATION:
            # In the hole, but further off its axis than the walls allow: sunk into one.
            return f"peg's section {1000 * m['wall_penetration']:.2f} mm into the hole's wall"
        # As deep as the hole's bottom or deeper, so the peg is not in it: it went down
        # beside the part (a hole near an edge), into another opening or through a gap.
        return f"peg went down beside the hole ({1000 * m['lateral_offset']:.1f} mm off the axis)"
    return f"peg stuck {1000 * m['tip_to_bottom']:.1f} mm above the hole's bottom"


def pose_residual(u) -> list[float]:
    """[lateral mm, tilt deg]: how far the peg tip is from the hole's axis and how far the
    peg's axis is from it (the pre-insertion pose has both at zero), from true poses."""
    H, T = u.hole_pose, u.tcp_matrix()
    z = H[:3, 2]
    d = T[:3, 3] - H[:3, 3]
    lateral = float(np.linalg.norm(d - (d @ z) * z))
    tilt = float(np.degrees(np.arccos(np.clip(-T[:3, 2] @ z, -1.0, 1.0))))
    return [round(1000 * lateral, 2), round(tilt, 2)]


def observe(env, obs) -> Observation:
    """What the agent is given of an observation: the robot's own sensors only (interface.py)."""
    u = env.unwrapped
    return Observation(
        obs=robot_view(obs),
        tcp_pose=u.tcp_matrix(),  # the tcp link's pose: forward kinematics of the joints
        qpos=u.agent.robot.get_qpos()[0].cpu().numpy().astype(np.float64),
        wrench=u.wrist_wrench(),
    )


def run_episode(
    env,
    agent: Agent,
    executor: Executor,
    seed: int,
    options: dict | None = None,
    film: Film | None = None,
):
    """Reset with `seed`, let the agent decide until it inserts or gives up, and score it.
    With `film`, the episode is filmed too (the caller writes the video)."""
    t0 = time.perf_counter()
    u = env.unwrapped
    name = getattr(agent, "name", type(agent).__name__)
    obs, _ = env.reset(seed=seed, options=options or {})
    failure = None
    try:
        agent.reset(agent_seed(seed))
    except AgentFailure as e:  # one that could not be built (registry.UnbuiltAgent)
        failure = e
    except Exception as e:  # an agent's bug is its episode's failure, not the run's
        failure = AgentFailure.of(name, 0, e)
    executor.reset(obs)
    if agent.privileged:  # the oracle's moves plan around the true object, not a view of it
        executor.know(u.object_surface())
    executor.on_step = None if film is None else film.on_step
    if film is not None:
        film.start()
    reason = ""
    inserted = False
    residuals: list[list[float]] = []
    decisions: list[str] = []
    try:
        if failure is not None:
            raise failure
        for k in range(agent.max_decisions):
            try:
                action = agent.act(observe(env, obs))
            except Exception as e:
                raise AgentFailure.of(name, k + 1, e) from e
            action = checked_action(action, name, k + 1)
            decisions.append(agent.phase or f"{action.kind} {k + 1}")
            if film is not None:
                film.note(decisions[-1], agent.estimate)
            if action.kind == "give_up":
                reason = f"agent gave up: {action.reason}"
                break
            if action.kind == "insert":
                depth = u.task.hole_depth + PRE_INSERT_HEIGHT + INSERT_OVERSHOOT
                res = executor.insert(depth, entry=PRE_INSERT_HEIGHT)
                inserted = res.ok
                reason = res.reason
                break
            res = executor.move_to(action.pose)
            residuals.append(pose_residual(u))
            if not res.ok:
                reason = res.reason
                break
            obs = executor.last_obs
        else:
            reason = f"no insertion after {agent.max_decisions} decisions"
    except AgentFailure as e:
        failure, reason = e, str(e)
    except FloatingPointError as e:
        reason = f"simulation blew up: {e}"
    m = {k: float(v[0]) for k, v in u.evaluate().items()}
    success = bool(m["success"]) and inserted
    if not success and not reason:
        reason = failure_reason(m, success_tilt_deg(u.task))
    if film is not None:
        executor.on_step = None
        film.finish(executor.servo_time, "success" if success else f"failure: {reason}")
    clean = {k: (v if math.isfinite(v) else float("nan")) for k, v in m.items()}
    return EpisodeResult(
        task=u.task.name,
        agent=name,
        object=u.episode_info["object"],
        seed=seed,
        init_error_m=round(u.episode_info["init_error_m"], 4),
        success=success,
        servo_time_s=round(executor.servo_time, 3),
        steps=executor.steps,
        planned_moves=executor.planned_moves,
        reason="" if success else reason,
        tilt_deg=round(u.episode_info["tilt_deg"], 2),
        tip_to_bottom_m=round(clean["tip_to_bottom"], 5),
        lateral_offset_m=round(clean["lateral_offset"], 5),
        peg_tilt_deg=round(clean["tilt_error_deg"], 3),
        wall_penetration_m=(
            round(m["wall_penetration"], 6) if math.isfinite(m["wall_penetration"]) else None
        ),
        wall_time_s=round(time.perf_counter() - t0, 3),
        sensor=u.sensor_profile.name,
        mount=u.camera_mount.name,
        provenance=provenance.of_episode(env, agent.weights, agent),
        move_residuals=residuals,
        decisions=decisions,
        agent_error=None if failure is None else failure.to_json(),
    )
