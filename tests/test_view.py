"""The approach yaw with a clear view (perception/view.py): which of a square peg's four
yaws keeps what stands on the face out of the wrist camera's line of sight."""

from __future__ import annotations

import numpy as np
import pytest

from cfvs_maniskill import geometry as G
from cfvs_maniskill.constants import PRE_INSERT_HEIGHT
from cfvs_maniskill.perception.view import (
    BLOCKED,
    approach_yaws,
    clear_view_yaw,
    sight_blockage,
)
from cfvs_maniskill.policies.interface import camera_in_tcp, insertion_pose

from .conftest import held_out_outcomes


def _scene(rng, wall_at: float | None = 0.06, tilt_deg: float = 0.0):
    """World points of a face around a hole at the origin (hole frame = world, unless
    tilted about y by `tilt_deg`), as a camera 20 cm above sees them: the face, and a wall
    2 cm thick and 10 cm tall whose near side is `wall_at` out on +x -- only its top and the
    end facing -y are in view, never the side the future line of sight would cross."""
    face = rng.uniform(-0.1, 0.1, size=(6000, 2))
    face = face[np.abs(face).max(axis=1) > 0.025]
    pts = [np.column_stack([face, np.zeros(len(face))])]
    if wall_at is not None:
        top = rng.uniform([wall_at, -0.06], [wall_at + 0.02, 0.06], size=(400, 2))
        pts.append(np.column_stack([top, np.full(len(top), 0.10)]))
        end = rng.uniform([wall_at, 0.0], [wall_at + 0.02, 0.10], size=(300, 2))
        pts.append(np.column_stack([end[:, 0], np.full(len(end), -0.06), end[:, 1]]))
    H = np.eye(4)
    H[:3, :3] = G.frame_with_z(
        np.array([np.sin(np.radians(tilt_deg)), 0.0, np.cos(np.radians(tilt_deg))]),
        np.array([1.0, 0.0, 0.0]),
    )
    return np.vstack(pts) @ H[:3, :3].T, H


def _poses(H: np.ndarray, first_x: np.ndarray) -> list[np.ndarray]:
    """Pre-insertion poses at the four yaws, in the order the agent tries them from a tool
    whose x is `first_x`: the nearest first, the two 90 deg turns, the half turn last."""
    tool = G.make(G.frame_with_z(-H[:3, 2], first_x), np.zeros(3))
    poses = approach_yaws(insertion_pose("square", H, -PRE_INSERT_HEIGHT, tool), first_x)
    x, y = poses[0][:3, 0], poses[0][:3, 1]  # the order these tests' indices assume
    assert all(np.allclose(P[:3, 0], a) for P, a in zip(poses, (x, y, -y, -x), strict=True))
    return poses


def _camera_side(P: np.ndarray, H: np.ndarray) -> np.ndarray:
    cam = P[:3, :3] @ camera_in_tcp() + P[:3, 3] - H[:3, 3]
    return np.round((cam @ H[:3, :3])[:2] / np.linalg.norm((cam @ H[:3, :3])[:2]))


@pytest.mark.parametrize("tilt", [0.0, 30.0])
def test_a_wall_between_camera_and_opening_turns_the_approach_to_a_clear_side(tilt):
    rng = np.random.default_rng(0)
    world, H = _scene(rng, tilt_deg=tilt)
    # The tool's x pointing at the wall puts the camera (11 cm out along x) behind it.
    poses = _poses(H, H[:3, 0])
    assert np.allclose(_camera_side(poses[0], H), [1.0, 0.0])
    i, counts = clear_view_yaw(world, poses, camera_in_tcp(), H)
    assert counts[0] >= 5 * BLOCKED, counts  # the wall's top stands over the line
    assert i == 1 and counts[1] < BLOCKED, counts  # the nearest clear yaw: a 90 deg turn
    assert not np.allclose(_camera_side(poses[i], H), [1.0, 0.0])


def test_nothing_standing_keeps_the_nearest_yaw():
    rng = np.random.default_rng(1)
    world, H = _scene(rng, wall_at=None, tilt_deg=40.0)
    poses = _poses(H, H[:3, 0])
    i, counts = clear_view_yaw(world, poses, camera_in_tcp(), H)
    assert i == 0 and max(counts) == 0, counts


def test_a_wall_beyond_the_camera_or_too_low_to_reach_the_line_does_not_block():
    rng = np.random.default_rng(2)
    far, H = _scene(rng, wall_at=0.16)  # past the camera's foot (11 cm out)
    low = _scene(rng, wall_at=0.06)[0]
    low[:, 2] = np.minimum(low[:, 2], 0.008)  # a 8 mm lip: under STANDING
    cam = _poses(H, H[:3, 0])[0]
    camera = cam[:3, :3] @ camera_in_tcp() + cam[:3, 3]
    assert sight_blockage(far, camera, H) == 0
    assert sight_blockage(low, camera, H) == 0


def test_all_blocked_keeps_the_nearest_yaw():
    rng = np.random.default_rng(3)
    world, H = _scene(rng)
    # Walls on all four sides (the same wall turned); the one on -y seen more sparsely.
    ring = [world]
    wall = world[world[:, 2] > 0.01]
    for k, step in ((1, 1), (2, 1), (3, 3)):
        a = k * np.pi / 2
        R = G.frame_with_z(np.array([0.0, 0.0, 1.0]), np.array([np.cos(a), np.sin(a), 0.0]))
        ring.append(wall[::step] @ R.T)
    i, counts = clear_view_yaw(np.vstack(ring), _poses(H, H[:3, 0]), camera_in_tcp(), H)
    assert min(counts) >= BLOCKED and int(np.argmin(counts)) == 1 and i == 0, counts


@pytest.mark.slow
def test_beside_a_tall_wall_the_clear_approach_inserts_where_the_nearest_yaw_does_not(
    make_env,
):
    """Held-out set C's wall bracket (an upright wall 10 cm tall, 2.5 cm from the hole),
    6-DoF, on `flange_side`, whose camera looks past the wall: at the yaw nearest the
    tool's the camera ends up behind the wall and the fine stage steers the peg onto the
    rim; at the clear yaw the coarse view chose, the same scene inserts. (From `tip_view`
    the opening shows from either yaw; a blind look's turns: test_cfvs.)"""
    outcome = held_out_outcomes(
        make_env,
        "PegInsert6DoF-v1",
        "heldout_c",
        "heldoutc_wall_bracket",
        203,
        {"nearest": {"clear_view": False, "look_again": False}, "clear": {}},
        camera_mount="flange_side",
    )
    assert not outcome["nearest"][0] and outcome["clear"][0], outcome
