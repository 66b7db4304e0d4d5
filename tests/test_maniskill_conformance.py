"""ManiSkill 3.0.1's generic env tests (its tests/test_envs.py and the wrapper/trajectory
tools), ported to our env ids: CPU physics, small step counts. Nothing here is skipped: none
of it needs GPU physics (`num_envs > 1`, which would, is refused with a clear error and
tested as such)."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import h5py
import imageio.v3 as iio
import numpy as np
import pytest
import torch
from mani_skill.utils import common
from mani_skill.utils.wrappers.gymnasium import CPUGymWrapper
from mani_skill.utils.wrappers.record import RecordEpisode

import cfvs_maniskill
from tests.conftest import run_cli

ENV_ID = "PegInsert6DoF-v1"
ALL_ENV_IDS = sorted(cfg.env_id for cfg in cfvs_maniskill.TASKS.values())
OBS_MODES = ["state_dict", "state", "rgbd", "pointcloud", "rgb", "depth+segmentation"]
CAMERA = (128, 128)


def assert_isinstance(x, types) -> None:
    if isinstance(x, dict):
        for v in x.values():
            assert_isinstance(v, types)
    else:
        assert isinstance(x, tuple(types)), type(x)


FLOAT_ATOL = 1e-6
"""ManiSkill's own check allows 1e-4. PhysX recomputes link poses from the restored joint
angles, which can differ from the simulated ones in the last bit (1e-7 m); 1 um is far
tighter than anything a wrong hole, object or noise stream would give."""
FLOAT_RTOL = 1e-4
"""For values that amplify it: the tilt in degrees, from float32 link rotations recomputed
by PhysX (measured: 1.1e-4 deg of 10.3 deg, relative 1.04e-5)."""


EDGE_PIXELS = 0.02
"""That last-bit camera pose moves the rasteriser's coverage of silhouette pixels: up to
this fraction of an image's pixels may differ, and in depth images (and clouds) only at
depth discontinuities. A wrong hole or object changes about 20% of them, anywhere."""
EDGE_JUMP = 0.005
"""A depth discontinuity: neighbouring pixels more than 5 mm apart."""
IMAGES = ("depth", "rgb", "segmentation", "xyzw")


def assert_obs_equal(a, b) -> None:
    """Equal key by key: integers exactly, floats within FLOAT_ATOL, images (and clouds)
    but for EDGE_PIXELS of their pixels."""
    a, b = common.to_numpy(a), common.to_numpy(b)
    if not isinstance(a, dict):
        a, b = {"": a}, {"": b}
    a, b = common.flatten_dict_keys(a), common.flatten_dict_keys(b)
    assert a.keys() == b.keys()
    for k in a:
        if k.split("/")[-1] in IMAGES:
            assert_images_equal(a[k], b[k], k)
        elif np.issubdtype(a[k].dtype, np.floating):
            np.testing.assert_allclose(a[k], b[k], rtol=FLOAT_RTOL, atol=FLOAT_ATOL, err_msg=k)
        else:
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)


# ------------------------------------------------------------------ every task, obs, control


@pytest.mark.parametrize("env_id", ALL_ENV_IDS)
def test_every_task_resets_and_steps(make_env, env_id):
    env = make_env(env_id, obs_mode="state")
    env.reset(seed=0)
    for _ in range(5):
        obs, rew, terminated, truncated, info = env.step(env.action_space.sample())
    assert torch.isfinite(obs).all() and torch.isfinite(rew).all()
    assert {"success", "fail", "elapsed_steps"} <= info.keys()


@pytest.mark.parametrize("obs_mode", OBS_MODES)
def test_obs_modes_with_cpu_gym_wrapper(make_env, obs_mode):
    env = CPUGymWrapper(make_env(ENV_ID, obs_mode=obs_mode))
    obs, _ = env.reset(seed=1)
    assert_isinstance(obs, [np.ndarray, bool, float, int])
    for _ in range(3):
        obs, rew, terminated, truncated, info = env.step(env.action_space.sample())
        assert_isinstance(obs, [np.ndarray, bool, float, int])
        assert isinstance(rew, float)
        assert isinstance(terminated, bool) and isinstance(truncated, bool)
        assert_isinstance(info, [np.ndarray, bool, float, int])
        struct = env.base_env.obs_mode_struct
        if obs_mode == "pointcloud":
            n = len(obs["pointcloud"]["xyzw"])
            assert obs["pointcloud"]["xyzw"].shape == (n, 4)
            assert obs["pointcloud"]["rgb"].shape == (n, 3)
            assert obs["pointcloud"]["segmentation"].shape == (n, 1)
            assert obs["pointcloud"]["segmentation"].dtype == np.int16
        elif isinstance(obs, dict):
            for cam in obs.get("sensor_data", {}):
                data, param = obs["sensor_data"][cam], obs["sensor_param"][cam]
                if struct.visual.rgb:
                    assert data["rgb"].shape == (*CAMERA, 3)
                if struct.visual.depth:
                    assert data["depth"].shape == (*CAMERA, 1) and data["depth"].dtype == np.int16
                if struct.visual.segmentation:
                    assert data["segmentation"].shape == (*CAMERA, 1)
                assert param["extrinsic_cv"].shape == (3, 4)
                assert param["intrinsic_cv"].shape == (3, 3)
                assert param["cam2world_gl"].shape == (4, 4)
        if struct.state:
            assert (obs["state"] if isinstance(obs, dict) else obs).ndim == 1
        if struct.state_dict:
            assert isinstance(obs, dict) and "agent" in obs and "extra" in obs


@pytest.mark.parametrize("obs_mode", OBS_MODES)
def test_obs_modes_without_wrapper(make_env, obs_mode):
    env = make_env(ENV_ID, obs_mode=obs_mode)
    obs, _ = env.reset(seed=1)
    assert_isinstance(obs, [torch.Tensor])
    for _ in range(3):
        obs, rew, terminated, truncated, info = env.step(env.action_space.sample())
        assert_isinstance(obs, [torch.Tensor])
        for x in (rew, terminated, truncated):
            assert isinstance(x, torch.Tensor) and x.shape == (1,)
        assert_isinstance(info, [torch.Tensor])
        if obs_mode == "pointcloud":
            n = obs["pointcloud"]["xyzw"].shape[1]
            assert obs["pointcloud"]["xyzw"].shape == (1, n, 4)
            assert obs["pointcloud"]["segmentation"].dtype == torch.int16
        elif isinstance(obs, dict) and "sensor_data" in obs:
            cam = obs["sensor_data"]["wrist_camera"]
            if "depth" in cam:
                assert cam["depth"].shape == (1, *CAMERA, 1) and cam["depth"].dtype == torch.int16
            if "rgb" in cam:
                assert cam["rgb"].shape == (1, *CAMERA, 3)
            assert obs["sensor_param"]["wrist_camera"]["extrinsic_cv"].shape == (1, 3, 4)


def test_every_control_mode_the_robot_declares(make_env):
    modes = list(make_env(ENV_ID, obs_mode="state").unwrapped.agent.supported_control_modes)
    assert {"pd_joint_pos_vel", "pd_joint_pos", "pd_joint_delta_pos"} <= set(modes)
    for mode in modes:
        env = make_env(ENV_ID, obs_mode="state", control_mode=mode)
        assert env.unwrapped.control_mode == mode
        env.reset(seed=2)
        q0 = env.unwrapped.agent.robot.get_qpos().clone()
        for _ in range(5):
            obs, *_ = env.step(env.action_space.sample())
        assert torch.isfinite(obs).all()
        assert not torch.equal(q0, env.unwrapped.agent.robot.get_qpos()), mode


# ------------------------------------------------------------------ seeding, NaN actions


def test_seeded_reset(make_env):
    env = make_env(ENV_ID, obs_mode="pointcloud")
    obs, _ = env.reset(seed=2000)
    for _ in range(5):
        env.step(env.action_space.sample())
    again, _ = env.reset(seed=2000)
    assert_obs_equal(obs, again)
    env.reset()
    again, _ = env.reset(seed=2000)
    assert_obs_equal(obs, again)


def test_seeded_reset_sequence():
    n = 17
    env = gym.make(ENV_ID, obs_mode="state", max_episode_steps=5, enhanced_determinism=True)
    try:
        env.reset(seed=2000)
        env.action_space.seed(0)
        actions = [env.action_space.sample() for _ in range(n)]
        for a in actions:
            first, _, _, truncated, _ = env.step(a)
            if truncated:
                first, _ = env.reset()
        env.reset(seed=2000)
        for a in actions:
            obs, _, _, truncated, _ = env.step(a)
            if truncated:
                obs, _ = env.reset()
    finally:
        env.close()
    assert_obs_equal(first, obs)


def test_nan_actions_raise_value_error(make_env):
    env = make_env(ENV_ID, obs_mode="state")
    env.reset(seed=2000)
    with pytest.raises(ValueError):
        env.step(env.action_space.sample() * np.nan)


def test_num_envs_above_one_is_refused_with_what_to_use_instead():
    with pytest.raises(ValueError) as e:
        gym.make(ENV_ID, num_envs=2)
    assert "num_envs=2" in str(e.value) and "--workers" in str(e.value)


# ------------------------------------------------------------------ state round trips


@pytest.mark.parametrize("api", ["dict", "flat"])
def test_state_round_trip_within_an_episode(make_env, api):
    env = make_env(ENV_ID, obs_mode="pointcloud")
    u = env.unwrapped
    env.reset(seed=1000)
    for _ in range(5):
        env.step(env.action_space.sample())
    state = u.get_state_dict() if api == "dict" else u.get_state()
    obs, ev = u.get_obs(), u.evaluate()
    for _ in range(50):
        env.step(env.action_space.sample())
    u.set_state_dict(state) if api == "dict" else u.set_state(state)
    assert_obs_equal(obs, u.get_obs())
    assert_obs_equal(ev, u.evaluate())


@pytest.mark.parametrize("obs_mode", ["state_dict", "state", "rgbd", "pointcloud"])
@pytest.mark.parametrize("api", ["dict", "flat"])
def test_state_round_trip_across_episodes(make_env, obs_mode, api):
    """Save in episode A, reset into B (another object), restore A: every observation,
    evaluate() and the rendered depth are A's again."""
    env = make_env(ENV_ID, obs_mode=obs_mode)
    u = env.unwrapped
    env.reset(seed=7, options={"object": "cylinder"})
    for _ in range(3):
        env.step(env.action_space.sample())
    state = u.get_state_dict() if api == "dict" else u.get_state()
    obs, ev, hole = u.get_obs(), u.evaluate(), u.hole_pose.copy()
    depth = _rendered_depth(u)

    env.reset(seed=8, options={"object": "cuboid_test_2"})
    env.step(env.action_space.sample())
    assert not np.array_equal(hole, u.hole_pose)
    with pytest.raises(AssertionError):
        assert_images_equal(depth, _rendered_depth(u), "rendered depth")

    u.set_state_dict(state) if api == "dict" else u.set_state(state)
    assert u.episode_info["object"] == "cylinder"
    np.testing.assert_allclose(hole, u.hole_pose, rtol=0, atol=FLOAT_ATOL)
    assert_obs_equal(obs, u.get_obs())
    assert_obs_equal(ev, u.evaluate())
    assert_images_equal(depth, _rendered_depth(u), "rendered depth")
    if obs_mode == "state_dict":
        assert "hole_pose" in obs["extra"]


STRAY_PIXELS = 8
"""Pixels allowed to differ beyond the rounding step away from any depth edge (of 16384):
full-suite runs have shown 2 to 5 such points where the same test alone
passes with none; a wrong or missing hole moves thousands."""


def assert_images_equal(a: np.ndarray, b: np.ndarray, what: str) -> None:
    assert a.shape == b.shape, what
    differ = ~np.isclose(a.astype(np.float64), b.astype(np.float64), rtol=0, atol=FLOAT_ATOL)
    per_pixel = differ.reshape(*a.shape[:-1], -1).any(-1)
    assert per_pixel.mean() <= EDGE_PIXELS, f"{what}: {per_pixel.mean():.2%} of pixels differ"
    if what.split("/")[-1] in ("depth", "xyzw", "rendered depth"):
        z = [_depth_image(x) for x in (a, b)]
        edges = _discontinuities(z[0]) | _discontinuities(z[1])
        # Away from edges, an int16 depth may round the other way (1 mm) and a cloud's
        # point move by ManiSkill's own tolerance, 0.1 mm (seen: 2 of 16384 points). In a
        # full-suite run a cloud once had 2 points beyond that away from edges (the same
        # test alone, and its file, pass): a few stray points are rasteriser noise; a
        # wrong or missing hole moves ~20% of them.
        step = 1.0 if np.issubdtype(a.dtype, np.integer) else 1e-4
        big = np.abs(a.astype(np.float64) - b.astype(np.float64)) > step
        stray = big.reshape(*a.shape[:-1], -1).any(-1).reshape(edges.shape) & ~edges
        assert stray.sum() <= STRAY_PIXELS, (
            f"{what}: {stray.sum()} pixels differ away from any edge"
        )


def _depth_image(x: np.ndarray) -> np.ndarray:
    """(H, W) depth in metres from a depth image (int16 mm or float m) or a cloud's xyzw."""
    millimetres = np.issubdtype(x.dtype, np.integer)  # ManiSkill's int16 depth
    x = x.reshape(-1, *CAMERA, x.shape[-1])[0].astype(np.float64)
    if x.shape[-1] == 4:  # a world-frame cloud: jumps in distance from the origin will do
        return np.linalg.norm(x[..., :3], axis=-1) * (x[..., 3] > 0)
    return x[..., 0] / 1000.0 if millimetres else x[..., 0]


def _discontinuities(z: np.ndarray) -> np.ndarray:
    """Pixels next to (or at) a depth jump, dilated by one pixel."""
    jump = np.zeros(z.shape, bool)
    dx, dy = np.abs(np.diff(z, axis=1)) > EDGE_JUMP, np.abs(np.diff(z, axis=0)) > EDGE_JUMP
    jump[:, 1:] |= dx
    jump[:, :-1] |= dx
    jump[1:] |= dy
    jump[:-1] |= dy
    out = jump.copy()
    out[1:] |= jump[:-1]
    out[:-1] |= jump[1:]
    out[:, 1:] |= jump[:, :-1]
    out[:, :-1] |= jump[:, 1:]
    return out


def _rendered_depth(u) -> np.ndarray:
    """The wrist camera's depth straight from the renderer (no noise)."""
    u.scene.update_render()
    cam = u.scene.sensors["wrist_camera"]
    cam.capture()
    return cam.get_obs(rgb=False, depth=True, segmentation=False)["depth"].numpy().copy()


def test_flat_state_of_the_wrong_length_names_what_was_expected(make_env):
    env = make_env(ENV_ID, obs_mode="state")
    u = env.unwrapped
    env.reset(seed=0)
    state = u.get_state()
    with pytest.raises(ValueError, match=f"expected {state.shape[-1]}"):
        u.set_state(state[:, :-1])


# ------------------------------------------------------------------ rendering, recording


@pytest.mark.parametrize("render_mode", ["rgb_array", "sensors", "all"])
def test_render_modes(make_env, render_mode):
    env = make_env(ENV_ID, obs_mode="state", render_mode=render_mode)
    env.reset(seed=0)
    img = env.render()
    assert img.ndim == 4 and img.shape[0] == 1 and img.shape[-1] == 3
    assert img.dtype == torch.uint8 and img.float().std() > 1  # a real picture, not blank


@pytest.mark.parametrize("info_on_video", [False, True])
def test_record_episode(tmp_path, info_on_video):
    env = gym.make(ENV_ID, obs_mode="state", max_episode_steps=8, render_mode="rgb_array")
    env = RecordEpisode(
        env, str(tmp_path), save_trajectory=True, save_video=True, info_on_video=info_on_video
    )
    env.reset(seed=5)
    for _ in range(8):
        env.step(env.action_space.sample())
    env.close()
    (h5,) = tmp_path.glob("*.h5")
    with h5py.File(h5) as f:
        assert f["traj_0/actions"].shape[0] == 8
        assert f["traj_0/env_states/task/noise"].shape == (9, 3)
    (video,) = tmp_path.glob("*.mp4")
    frames = iio.imread(video)
    assert len(frames) == 9 and frames.shape[-1] == 3


@pytest.mark.slow
def test_replay_trajectory_round_trip(tmp_path):
    """Record random actions with RecordEpisode, replay them with ManiSkill's own
    replay_trajectory (through `python -m cfvs_maniskill.tool`): the replayed states equal
    the recorded ones; converting to the point-cloud obs mode with env states works."""
    steps = 10
    env = gym.make(ENV_ID, obs_mode="state", max_episode_steps=steps)
    env = RecordEpisode(env, str(tmp_path), save_trajectory=True, save_video=False)
    env.reset(seed=3)
    env.action_space.seed(3)
    for _ in range(steps):
        env.step(env.action_space.sample())
    env.close()
    (h5,) = tmp_path.glob("*.h5")
    meta = json.loads(h5.with_suffix(".json").read_text())
    assert meta["env_info"]["env_id"] == ENV_ID

    r = run_cli("cfvs_maniskill.tool", "replay_trajectory", "--traj-path", str(h5),
                "--save-traj", "--allow-failure")  # fmt: skip
    assert r.returncode == 0, r.stderr[-3000:]
    replayed = tmp_path / f"{h5.stem}.state.pd_joint_pos_vel.physx_cpu.h5"
    with h5py.File(h5) as a, h5py.File(replayed) as b:
        for key in ("env_states/articulations", "env_states/actors", "env_states/task"):
            for name in a[f"traj_0/{key}"]:
                np.testing.assert_array_equal(
                    a[f"traj_0/{key}/{name}"][()], b[f"traj_0/{key}/{name}"][()], err_msg=name
                )
        np.testing.assert_array_equal(a["traj_0/obs"][()], b["traj_0/obs"][()])

    r = run_cli("cfvs_maniskill.tool", "replay_trajectory", "--traj-path", str(h5),
                "-o", "pointcloud", "--save-traj", "--save-video", "--use-env-states",
                "--allow-failure")  # fmt: skip
    assert r.returncode == 0, r.stderr[-3000:]
    converted = tmp_path / f"{h5.stem}.pointcloud.pd_joint_pos_vel.physx_cpu.h5"
    with h5py.File(converted) as f:
        assert f["traj_0/obs/pointcloud/xyzw"].shape == (steps + 1, 128 * 128, 4)


@pytest.mark.slow
def test_stock_demo_runs_with_its_default_flags():
    """ManiSkill's demo passes render_backend="gpu" by default: on a machine without a GPU
    it falls back to SwiftShader with one warning line."""
    r = run_cli("mani_skill.examples.demo_random_action", "-e",
                f"cfvs_maniskill:{ENV_ID}", "--quiet")  # fmt: skip
    assert r.returncode == 0, r.stderr[-3000:]
    if not Path("/dev/dri").exists() and not Path("/dev/nvidia0").exists():
        assert r.stderr.count("rendering on SwiftShader") == 1
