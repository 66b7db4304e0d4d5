"""Moves plan around what the camera has seen, and every scene the task samples is one
the arm can solve."""

from __future__ import annotations

import numpy as np

from cfvs_maniskill.control.executor import Executor, _gap
from cfvs_maniskill.session import open_session


def test_a_move_plans_around_a_seen_obstacle_on_its_straight_line(make_env):
    env = make_env("PegInsert6DoF-v1", obs_mode="pointcloud", init_error="large")
    u = env.unwrapped
    obs, _ = env.reset(seed=11)
    ex = Executor(env)
    ex.reset(obs)
    target = u.insertion_pose(-0.03)
    q0 = ex.robot.joints()
    start = u.tcp_matrix()
    line, _ = ex._straight_path(start, target, q0, *_gap(start, target))
    assert ex.planner.path_free([q0, *line]), "the scene's own straight line is free"
    # A 4 cm block of seen points where one of the arm's links passes halfway along the
    # line, clear of where the arm starts and ends.
    planner, halfway = ex.planner, line[len(line) // 2]
    grid = np.stack(np.meshgrid(*[np.linspace(-0.02, 0.02, 5)] * 3), -1).reshape(-1, 3)
    hulls = planner.collision.hulls
    for h, T in zip(hulls, u.kinematics.link_poses(halfway, [h.index for h in hulls]), strict=True):
        planner.world.clear()
        planner.world.add_points(T[:3, :3] @ h.centre + T[:3, 3] + grid)
        if planner.blocked_by(q0) is None and planner.blocked_by(line[-1]) is None:
            break
    else:
        raise AssertionError("no link's halfway place is clear of the start and the goal")
    assert not planner.path_free([q0, *line])
    block, tree = planner.world.points.copy(), planner.world.tree
    path = planner.plan(q0, target)
    assert np.allclose(path[0], q0) and u.kinematics._reaches(path[-1], target)
    visited = []
    ex.on_step = lambda e: visited.append(e.robot.joints())
    result = ex.move_to(target)
    assert result.ok, result.reason
    assert ex.planned_moves == 1
    # The arm lags its commanded path; the planner's margin covers that lag.
    touching = [q for q in visited if planner.collision.touches(q, block, tree, 0.0)]
    assert not touching, f"{len(touching)} of {len(visited)} steps touch the block"


def test_the_oracle_solves_a_scene_whose_first_arm_branch_dipped_into_the_table(make_env):
    """PegInsert6DoF, cuboid_test_2 at 30 cm: the IK branch from home put the upper arm
    into the table and the oracle's move stopped 22 cm short."""
    env = make_env(
        "PegInsert6DoF-v1", obs_mode="state", objects=["cuboid_test_2"], init_error="large"
    )
    session = open_session(env, "oracle")
    result = session.episode(731383209)
    assert result.success, result.reason
    # Without a camera, its planner knew the whole true object, within a voxel.
    world = session.executor.planner.world
    gap, _ = world.tree.query(env.unwrapped.object_surface())
    assert gap.max() <= np.sqrt(3) / 2 * world.voxel


def test_a_path_check_finds_the_first_configuration_and_link_one_at_a_time_would(make_env):
    """The batched check of a path (first_touch) against `touches` configuration by
    configuration: random arms near home among random points, with and without a margin."""
    from scipy.spatial import cKDTree

    env = make_env("PegInsert6DoF-v1", obs_mode="state")
    u = env.unwrapped
    env.reset(seed=1)
    home = u.agent.robot.get_qpos()[0].cpu().numpy().astype(np.float64)
    rng = np.random.default_rng(0)
    seen = set()
    for trial in range(12):
        points = rng.uniform([0.2, -0.4, 0.0], [0.8, 0.4, 0.3], (rng.integers(5, 400), 3))
        tree = cKDTree(points)
        qs = [home + rng.normal(0, 0.3, len(home)) for _ in range(60)]
        margin = (0.0, 0.01)[trial % 2]
        one_by_one = [u.collision.touches(q, points, tree, margin) for q in qs]
        seen.update(one_by_one)
        for start in range(0, 60, 7):
            expect = next(((i, n) for i, n in enumerate(one_by_one[start:]) if n is not None), None)
            assert u.collision.first_touch(qs[start:], points, tree, margin, chunk=8) == expect
    assert None in seen and len(seen) >= 4, seen  # free arms and several links touching
