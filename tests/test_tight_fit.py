"""Tight-fit tasks: task files, the chamfered peg, the wrist force reading and a
contact model that behaves at 0.5 mm clearance (no tunnelling, no explosion, jams scored
as failures)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cfvs_maniskill import geometry as G
from cfvs_maniskill import resources
from cfvs_maniskill.constants import (
    PEG_LENGTH,
    PRE_INSERT_HEIGHT,
    SQUARE_PEG_SIDE,
    SUCCESS_WALL_PENETRATION,
)
from cfvs_maniskill.control.executor import Executor, ExecutorConfig
from cfvs_maniskill.control.force_insert import (
    ForceInsertConfig,
    Outcome,
    Phase,
    next_phase,
    spiral_pitch,
    tip_wrench,
)
from cfvs_maniskill.control.spiral import SpiralSearch, stalled
from cfvs_maniskill.envs.scene import wall_penetration
from cfvs_maniskill.envs.task_config import TaskConfigError, load_task
from cfvs_maniskill.episode import run_episode
from cfvs_maniskill.policies.oracle.agent import OracleAgent
from cfvs_maniskill.policies.registry import make_agent
from cfvs_maniskill.robots.peg import chamfered_peg_mesh

TIGHT = "PegInsert6DoF-0.5mm-v1"


def test_tight_task_files(tmp_path):
    for name, clearance in (("PegInsert6DoF-1mm", 0.001), ("PegInsert6DoF-0.5mm", 0.0005)):
        cfg = load_task(resources.bundled("tasks") / f"{name}.yaml")
        assert cfg.clearance == clearance and cfg.peg_chamfer == 0.0015 and cfg.dof == 6
        assert cfg.contact_offset == clearance / 2  # the play per side (TaskConfig says why)
    paper = load_task(resources.bundled("tasks") / "PegInsert6DoF.yaml")
    assert paper.pcm is False and paper.contact_offset == 0.002  # exact contacts everywhere
    # A task file without a contact offset gets 2 mm, or half its clearance if less.
    offsets = {}
    for clearance in (0.004, 0.002, 0.0005):
        p = resources.bundled("tasks") / "PegInsert6DoF.yaml"
        mine = p.read_text().replace("clearance: 0.004", f"clearance: {clearance}")
        q = tmp_path / f"Mine{clearance}.yaml"
        q.write_text(mine)
        offsets[clearance] = load_task(q).contact_offset
    assert offsets == {0.004: 0.002, 0.002: 0.001, 0.0005: 0.00025}
    # The spiral's turns are never further apart than the band the peg can drop in from.
    assert spiral_pitch(0.0012, 0.0005, 0.0) == 0.00025
    assert spiral_pitch(0.0012, 0.004, 0.0) == 0.0012


@pytest.mark.parametrize(
    ("line", "words"),
    [
        ("peg_chamfer: 0.02", "peg_chamfer"),
        ("peg_chamfer: -0.001", "peg_chamfer"),
        ("peg_chamfer: 1mm", "expected a number"),
        ("clearance: '0.5mm'", "expected a number"),
        ("pcm: off-ish", "expected true or false"),
        ("pcm: 0", "expected true or false"),
        ("contact_offset: 0", "contact_offset"),
        ("contact_offset: 0.05", "contact_offset"),
        ("contact_offset: 2mm", "expected a number"),
        ("clearance: 0.0003\ncontact_offset: 0.0002", "expected contact_offset <= 0.00015 m"),
        ("clearance: 0.002\ncontact_offset: 0.002", "expected contact_offset <= 0.001 m"),
        ("dof: 4\ntilt_deg: [0, 30]", "expected [0, 0] for dof 4"),  # agents keep it vertical
        ("dof: 3", "init_roll_deg (45) plus the largest |yaw_deg| (0) is 45: expected at most"),
    ],
)
def test_bad_tight_fields_name_the_field(tmp_path, line, words):
    p = tmp_path / "Mine.yaml"
    p.write_text(f"peg: square\n{line}\n")
    with pytest.raises(TaskConfigError) as e:
        load_task(p)
    assert str(p) in str(e.value) and line.split(":")[0] in str(e.value) and words in str(e.value)


def test_spiral_search_covers_the_disc_without_gaps():
    pitch, radius, dt = 0.0005, 0.004, 0.05
    s = SpiralSearch(pitch, 0.008, radius, stalled_at=0.0, min_radius=pitch / 4)
    pts = []
    while (p := s.step(dt)) is not None:
        pts.append(p[:2])
    pts = np.array(pts)
    r = np.linalg.norm(pts, axis=1)
    assert r[0] < pitch  # starts at the centre
    assert np.all(np.diff(r) > 0) and r[-1] <= radius
    steps = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    assert steps[5:].max() < 1.05 * 0.008 * dt  # walks at the search speed
    # Every point of the disc is within a pitch of the path: nothing the peg could drop
    # into is skipped.
    g = np.mgrid[-0.0035:0.0035:40j, -0.0035:0.0035:40j].reshape(2, -1).T
    g = g[np.linalg.norm(g, axis=1) < radius - pitch]
    gap = np.linalg.norm(g[:, None] - pts[None], axis=2).min(axis=1)
    assert gap.max() < pitch
    assert stalled([0.0, 0.0001, 0.0002, 0.0003], 3) and not stalled([0.0, 0.0003, 0.0006], 2)
    assert not stalled([0.0, 0.0], 3)  # too short a history to tell


def test_admittance_yields_to_the_measured_moment():
    """A peg pointing down (tip at the origin) carries a rim's upward push on its +x side:
    the command yields (that side rises: the face lays flat on the rim). A wall's push up
    the peg (+x push on its -x side) turns the top away from the wall. The same in every
    phase (force_insert turns by rot_gain x moment): the wrist sensor's one wrench cannot
    tell an axial load from a wall's push."""
    corner = np.array([0.023, 0.0, 0.002])  # on the peg's +x side, 2 mm above the tip
    moment = np.cross(corner, np.array([0.0, 0.0, 10.0]))
    wall = np.cross(np.array([-0.023, 0.0, 0.02]), np.array([8.0, 0.0, 0.0]))
    top = np.array([0.0, 0.0, 0.05])
    gain = ForceInsertConfig().rot_gain
    assert (Rotation.from_rotvec(gain * moment).apply(corner) - corner)[2] > 1e-5
    assert (Rotation.from_rotvec(gain * wall).apply(top) - top)[0] > 1e-6


def test_insertion_phases_follow_travel_and_first_touch():
    """RIM -> PASSING 1 mm past the first touch (not before a touch, not after a search
    started); any phase -> HOLE 3 mm past the chamfer's end; only the insertion's own
    failures fail the move (a searched spiral leaves the verdict to the score)."""
    f, entry, chamfer = ForceInsertConfig(), 0.03, 0.0015
    assert next_phase(Phase.RIM, 0.0305, entry, chamfer, None, False, f) is Phase.RIM
    assert next_phase(Phase.RIM, 0.0305, entry, chamfer, 0.030, False, f) is Phase.RIM
    assert next_phase(Phase.RIM, 0.0312, entry, chamfer, 0.030, False, f) is Phase.PASSING
    assert next_phase(Phase.RIM, 0.0312, entry, chamfer, 0.030, True, f) is Phase.RIM
    assert next_phase(Phase.PASSING, 0.0346, entry, chamfer, 0.030, False, f) is Phase.HOLE
    assert next_phase(Phase.RIM, 0.0346, entry, chamfer, None, True, f) is Phase.HOLE
    assert Outcome.ENDED.peg_is_in_place and Outcome.SPIRAL_EXHAUSTED.peg_is_in_place
    assert not Outcome.TIMED_OUT.peg_is_in_place and not Outcome.UNREACHABLE.peg_is_in_place
    assert Outcome.UNREACHABLE.reason == "insertion path unreachable"


def test_wrist_wrench_moved_to_the_tip():
    """The flange reading of a push at the tip has the push's moment about the flange; moved
    to the tip it has none."""
    flange = np.eye(4)
    flange[:3, :3] = Rotation.from_euler("xyz", [0.3, -0.2, 1.0]).as_matrix()
    flange[:3, 3] = [0.4, 0.1, 0.3]
    tip = flange[:3, 3] + PEG_LENGTH * flange[:3, 2]
    f_world = np.array([2.0, -1.0, 5.0])
    m_flange_world = np.cross(tip - flange[:3, 3], f_world)
    R = flange[:3, :3]
    reading = np.concatenate([R.T @ f_world, R.T @ m_flange_world])
    force, moment = tip_wrench(reading, flange, tip)
    assert np.allclose(force, f_world) and np.allclose(moment, 0.0, atol=1e-12)


def test_chamfered_peg_mesh():
    m = chamfered_peg_mesh("square", 0.0015)
    assert m.is_watertight and m.is_convex
    tip = m.vertices[np.isclose(m.vertices[:, 2], PEG_LENGTH)]
    assert np.allclose(np.abs(tip[:, :2]).max(axis=0), SQUARE_PEG_SIDE / 2 - 0.0015)
    assert np.isclose(m.vertices[:, :2].max(), SQUARE_PEG_SIDE / 2)
    box = SQUARE_PEG_SIDE**2 * PEG_LENGTH
    assert 0.99 * box < m.volume < box  # only the edges are cut
    r = chamfered_peg_mesh("round", 0.001)
    assert r.is_convex and np.isclose(r.vertices[:, 2].max(), PEG_LENGTH)


def _hole_z_force(env) -> float:
    u = env.unwrapped
    force, _ = u.contact_wrench()
    return float(force @ u.hole_pose[:3, 2])


@pytest.mark.slow
def test_tight_fit_contact_model(make_env):
    env = make_env(TIGHT, obs_mode="state")
    u = env.unwrapped
    assert u.agent.robot.links_map["peg"] is not None and "chamfer" in u.agent.uid

    # The true pose: every episode ends at rest (no explosion), scored with its reason,
    # and the tip never passes the floor although the insertion is commanded 1 cm past it.
    # The true pose goes in on every scene (80 of 80 measured at 0.5 mm, docs/tight-fits.md).
    ex = Executor(env)
    assert ex.insertion_mode == "force"
    oracle = OracleAgent(env)
    results = [run_episode(env, oracle, ex, seed=seed) for seed in range(4)]
    assert all(r.success for r in results), [r.reason for r in results]
    for r in results:
        assert r.tip_to_bottom_m > -0.001, r  # the floor holds
        if r.success:
            assert r.lateral_offset_m < 0.0005
    qd = u.agent.robot.get_qvel()[0].cpu().numpy()
    assert np.all(np.isfinite(qd)) and np.abs(qd).max() < 0.5

    # 2 mm off the axis with the paper's position-controlled insertion and no search: the
    # peg must stay on the rim (no tunnelling through 0.25 mm of play), pressing on it with
    # a bounded force that the wrist reading sees, and the episode is scored a failure.
    plain = Executor(env, ExecutorConfig(insertion="position", search_radius=0.0))
    env.reset(seed=3)
    plain.reset()
    P = u.insertion_pose(-PRE_INSERT_HEIGHT)
    P[:3, 3] += 0.002 * P[:3, 0]
    assert plain.move_to(P).ok
    plain.insert(u.task.hole_depth + PRE_INSERT_HEIGHT + 0.01, entry=PRE_INSERT_HEIGHT)
    m = {k: float(v[0]) for k, v in u.evaluate().items()}
    assert m["tip_depth"] < 0.0015 and not m["success"]
    push = _hole_z_force(env)
    assert 5.0 < push < 200.0, push  # the rim pushes the peg back out, tens of newtons

    # A peg jammed 4 degrees askew is reported as not inserted, with its reason.
    env.reset(seed=4)
    plain.reset()
    P = u.insertion_pose(-PRE_INSERT_HEIGHT)
    tilt = np.eye(4)
    tilt[:3, :3] = G.frame_with_z(
        np.array([np.sin(np.radians(4)), 0, np.cos(np.radians(4))]), np.array([1.0, 0, 0])
    )
    assert plain.move_to(P @ tilt).ok
    plain.insert(u.task.hole_depth + PRE_INSERT_HEIGHT + 0.01, entry=PRE_INSERT_HEIGHT)
    m = {k: float(v[0]) for k, v in u.evaluate().items()}
    assert not m["success"] and m["tip_to_bottom"] > 0.01
    assert np.all(np.isfinite(u.tcp_matrix()))


@pytest.mark.slow
def test_true_pose_goes_in_where_contacts_held_it(make_env):
    """The true pre-insertion pose, 0.5 mm clearance, on seven scenes where it once stopped
    1.7 mm into the entry (centred within 0.06 mm): PhysX reported the peg's chamfer, its
    plane extended, touching the hole's corners while the walls were 0.25 mm away, and the
    spiral search dragged the peg off. With a 2 mm contact offset the first four stopped;
    with half the clearance (the task's, carried by the scene's shapes) seeds 25, 108, 120
    and 154 still did when run alone, until a stalled peg backed off and pushed again."""
    env = make_env(TIGHT, obs_mode="state")
    u = env.unwrapped
    oracle, ex = OracleAgent(env), Executor(env)
    for seed in (11, 20, 22, 25, 108, 120, 154):
        r = run_episode(env, oracle, ex, seed=seed)
        assert r.success, (seed, r.reason)
    peg = u.agent.robot.links_map["peg"]._objs[0]
    assert all(abs(s.contact_offset - 0.00025) < 1e-9 for s in peg.collision_shapes)


@pytest.mark.slow
def test_the_walls_hold_a_peg_pushed_across_the_play(make_env):
    """A seated peg (1 mm clearance) commanded 2 mm across the hole in 4 s, 1.5 mm past the
    far wall: the wall stops it. With a contact distance shorter than the play (0.2 mm
    offsets), PhysX made that wall's contacts only once the peg was 0.54 mm inside it."""
    env = make_env("PegInsert6DoF-1mm-v1", obs_mode="state")
    u = env.unwrapped
    ex = Executor(env)
    assert run_episode(env, OracleAgent(env), ex, seed=1).success
    H, T, q = u.hole_pose, u.tcp_matrix(), ex.robot.joints()
    deepest = -1.0
    for k in range(1, 81):
        P = T.copy()
        P[:3, 3] -= H[:3, 0] * 0.002 * k / 80
        q, ok = ex.step_towards(P, q)
        assert ok
        deepest = max(deepest, wall_penetration(u.task, G.inv(u.hole_pose) @ u.tcp_matrix()))
    assert deepest < SUCCESS_WALL_PENETRATION, deepest


@pytest.mark.slow
def test_cfvs_seats_pegs_that_stale_contacts_used_to_jam(make_env):
    """CFVS on two 1 mm episodes whose pegs ended 1.5 deg askew and < 0.3 mm off the axis
    (room to spare: at 3 mm in they need 0.08 mm of the 0.5 mm on each side). With PhysX's
    persistent contact manifold both stuck 2-3 mm into the entry, held by stale contacts on
    both rim edges; with exact contacts (`pcm: false`, every task's default) both go in."""
    env = make_env("PegInsert6DoF-1mm-v1", obs_mode="pointcloud")
    agent, ex = make_agent("cfvs", env), Executor(env)
    for seed in (5000, 5012):
        r = run_episode(env, agent, ex, seed=seed)
        assert r.success, (seed, r.reason)


@pytest.mark.slow
def test_cfvs_straightens_tilted_pegs_passing_the_rim(make_env):
    """CFVS on two 0.5 mm episodes (unseen test object) whose pegs once stopped 2.2-2.6 mm
    into the entry, tilted ~2 deg: the high side's chamfer on one rim edge, the low side
    against the opposite wall. With the wrist wrench, the 3 deg turn limit and the spiral
    fallback of the passing phase they go in."""
    env = make_env(TIGHT, obs_mode="pointcloud")
    agent, ex = make_agent("cfvs", env), Executor(env)
    for seed in (913002097, 933831750):
        r = run_episode(env, agent, ex, seed=seed, options={"object": "cuboid_test_1"})
        assert r.success, (seed, r.reason)


@pytest.mark.slow
def test_cfvs_keeps_the_peg_square_while_searching_the_rim(make_env):
    """CFVS under `realistic` on two 0.5 mm episodes (30 cm) whose pegs end the fine loop
    2-3 mm off (the hand-eye error) and rest partly over the opening; yielding to that
    moment while the spiral dragged them about, such pegs reached the opening 3.6 deg
    askew and jammed 3 mm in. Bounded to 1 deg from the start pose on the rim, both go in.
    (The cylinder's scene is one that jammed; the cuboid's, 2.9 mm off after the fine
    loop, is from results/square_fit_dev/retrained_tight: the scene that jammed there
    before jams 1.8 mm in with the retrained square net.)"""
    env = make_env(TIGHT, obs_mode="pointcloud", sensor="realistic", init_error="large")
    agent, ex = make_agent("cfvs", env), Executor(env)
    for obj, seed in (("cuboid_test_2", 1992906686), ("cylinder", 1090663628)):
        r = run_episode(env, agent, ex, seed=seed, options={"object": obj})
        assert r.success, (obj, seed, r.reason)
