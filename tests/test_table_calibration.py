"""Self-calibration against the table: the depth scale and the mount's tilt come back from
the table plane, whatever the hole."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from cfvs_maniskill.perception.table_calibration import correction_from_table


def _camera(height: float = 0.3, tilt_deg: float = 20.0) -> np.ndarray:
    """A camera `height` above the table, looking down and tilted about x (z: its view axis
    in world terms does not matter to the correction, only its pose)."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xy", [180.0 + tilt_deg, 5.0], degrees=True).as_matrix()
    T[:3, 3] = [0.45, 0.05, height]
    return T


def _scene(rng: np.random.Generator, n: int = 6000) -> np.ndarray:
    """True world points: the table top round the camera's foot, and a block standing on it."""
    table = np.column_stack([rng.uniform(0.25, 0.65, n), rng.uniform(-0.15, 0.25, n), np.zeros(n)])
    block = np.column_stack(
        [rng.uniform(0.4, 0.5, n // 3), rng.uniform(0.0, 0.1, n // 3), rng.uniform(0, 0.07, n // 3)]
    )
    return np.concatenate([table, block])


def _reported(true: np.ndarray, camera: np.ndarray, scale: float, turn: np.ndarray) -> np.ndarray:
    """Where a camera with depth scale `scale` and a mount turned by `turn` (world axes, about
    the camera) reports the true points, plus 0.5 mm of noise."""
    c = camera[:3, 3]
    p = (true - c) @ turn.T * scale + c
    return p + np.random.default_rng(1).normal(0, 0.0005, p.shape)


def _seen(points: np.ndarray) -> np.ndarray:
    """The points as a cloud's valid world points (float32)."""
    return points.astype(np.float32)


def test_scale_and_tilt_of_the_camera_come_back_from_the_table():
    rng = np.random.default_rng(0)
    camera, true = _camera(), _scene(rng)
    turn = Rotation.from_rotvec(np.radians([0.4, -0.3, 0.0])).as_matrix()
    seen = _reported(true, camera, 1.02, turn)
    corr = correction_from_table(_seen(seen), camera)
    assert corr is not None
    assert abs(corr.scale * 1.02 - 1.0) < 5e-4
    fixed = corr.apply(seen, camera)
    block = slice(6000, None)  # the part, never used by the fit, lands where it is
    before = np.linalg.norm(seen[block] - true[block], axis=1).mean()
    after = np.linalg.norm(fixed[block] - true[block], axis=1).mean()
    assert before > 0.004 and after < 0.001, (before, after)


def test_the_correction_found_in_one_view_holds_at_another_pose():
    """The errors are fixed to the camera: a correction measured from one pose repairs a
    cloud taken from another (the fine stage's views after the coarse one)."""
    rng = np.random.default_rng(2)
    true = _scene(rng)
    mount = Rotation.from_rotvec(np.radians([0.3, 0.35, 0.0])).as_matrix()  # camera frame
    first, later = _camera(0.32, 15.0), _camera(0.18, 35.0)

    def view(camera):
        R = camera[:3, :3]
        return _reported(true, camera, 0.985, R @ mount @ R.T)

    corr = correction_from_table(_seen(view(first)), first)
    assert corr is not None
    seen = view(later)
    err = np.linalg.norm(corr.apply(seen, later)[6000:] - true[6000:], axis=1).mean()
    assert err < 0.001 < np.linalg.norm(seen[6000:] - true[6000:], axis=1).mean()


def test_a_calibrated_camera_is_left_as_it_is():
    rng = np.random.default_rng(3)
    camera, true = _camera(), _scene(rng)
    corr = correction_from_table(_seen(_reported(true, camera, 1.0, np.eye(3))), camera)
    assert corr is not None and abs(corr.scale - 1) < 2e-4 and corr.tilt_deg < 0.02


def test_no_correction_without_enough_table_or_from_a_plane_that_is_not_the_table():
    rng = np.random.default_rng(4)
    camera = _camera()
    only_block = _scene(rng)[6000:]
    assert correction_from_table(_seen(only_block), camera) is None
    # A plane 2 cm up (a large flat face near the table's height) is not the table.
    raised = _scene(rng)[:6000] + [0, 0, 0.015]
    assert correction_from_table(_seen(raised), camera) is None


def test_cfvs_finds_the_episodes_depth_scale_and_mount_tilt_from_its_first_view(make_env):
    """Under the D405 profile, the agent's correction from the coarse view against the
    episode's true errors (read from the simulator here, never by the agent): the depth scale
    within 0.7% (the mount's 1.5 mm translation along the table's normal is taken as scale)
    and the mount's tilt about the horizontal axes within 0.25 deg, in every one of 4 scenes."""
    from cfvs_maniskill.policies.base import Observation
    from cfvs_maniskill.policies.cfvs.agent import CFVSAgent
    from cfvs_maniskill.policies.interface import TaskSpec, robot_view
    from cfvs_maniskill.sensing.model import SAPIEN_CAM_TO_GL

    env = make_env("PegInsert6DoF-v1", obs_mode="pointcloud", sensor="realistic")
    u = env.unwrapped
    agent = CFVSAgent(TaskSpec.of(u.task))
    for seed in range(4):
        obs, _ = env.reset(seed=seed)
        agent.reset(seed)
        tcp = u.tcp_matrix()
        agent.act(Observation(obs=robot_view(obs), tcp_pose=tcp))
        corr = agent.correction
        assert abs(1 / corr.scale - u.sensing.depth_errors.scale) < 0.007
        gl = obs["sensor_param"]["wrist_camera"]["cam2world_gl"][0].cpu().numpy()
        cam = (gl @ np.linalg.inv(SAPIEN_CAM_TO_GL))[:3, :3]
        true = Rotation.from_matrix(cam @ u.sensing.mount[:3, :3] @ cam.T).as_rotvec()
        found = Rotation.from_matrix(tcp[:3, :3] @ corr.rotation @ tcp[:3, :3].T).as_rotvec()
        assert np.degrees(np.abs(true[:2] - found[:2])).max() < 0.25, (seed, true, found)
