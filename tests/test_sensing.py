"""Sensor profiles: the realistic depth model's statistics and edge model, the
hand-eye error, the wrist force/torque sensor, profile files and their errors."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from cfvs_maniskill import geometry as G
from cfvs_maniskill import resources
from cfvs_maniskill.constants import PRE_INSERT_HEIGHT
from cfvs_maniskill.control.executor import Executor, ExecutorConfig
from cfvs_maniskill.robots.ur5 import CAMERA_UID, camera_pose_in_tool
from cfvs_maniskill.sensing.depth import apply_stereo, discontinuity_jump, edge_mask, grid_points
from cfvs_maniskill.sensing.floor import (
    camera_in_tip,
    floor_samples,
    hand_eye_residual,
    pre_insertion_hole,
)
from cfvs_maniskill.sensing.model import SAPIEN_CAM_TO_GL, mount_error
from cfvs_maniskill.sensing.profile import (
    SensorProfileError,
    available_profiles,
    load_profile,
)
from tests.conftest import run_cli

REALISTIC = load_profile("realistic")
K = np.array([[91.4, 0.0, 64.0], [0.0, 91.4, 64.0], [0.0, 0.0, 1.0]])
"""The wrist camera's intrinsics (128 px, 70 deg)."""


def _profile_file(tmp_path: Path, name: str, **sections) -> Path:
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(sections))
    return path


# ------------------------------------------------------------------ depth model


def _axial_std(model, z: float) -> float:
    """The profile's predicted depth noise at z: disparity noise through d = fB/z, plus
    the disparity's and the depth unit's quantisation (uniform: step^2 / 12)."""
    gain = z * z / (model.focal_px * model.baseline)
    var = (gain * model.disparity_noise_px) ** 2
    var += (gain * model.disparity_step_px) ** 2 / 12 + model.depth_unit**2 / 12
    return float(np.sqrt(var))


@pytest.mark.parametrize("z", [0.15, 0.30, 0.45])
def test_flat_plate_has_the_profiles_noise_statistics(z):
    """A plate facing the camera at z: unbiased, with the predicted axial spread (within
    20%), growing with z^2 (stereo), nothing dropped away from its edges."""
    model = REALISTIC.depth
    plate = grid_points(np.full((128, 128), z, np.float32), K)
    rng = np.random.default_rng(0)
    out, ok = apply_stereo(plate, np.ones((128, 128), bool), model, rng, 1 / K[0, 0])
    inner = ok[2:-2, 2:-2]
    assert inner.all()
    dz = out[2:-2, 2:-2, 2].astype(np.float64) - z
    want = _axial_std(model, z)
    assert abs(dz.std() / want - 1) < 0.2, (dz.std(), want)
    assert abs(dz.mean()) < 0.2 * want + model.depth_unit
    # The ray through each pixel moves by the lateral noise only (sub-millimetre here).
    ray = out[..., :2] / out[..., 2:]
    lateral = (ray - plate[..., :2] / z)[2:-2, 2:-2] * z
    assert abs(lateral.std() / (model.lateral_noise_px / model.focal_px * z) - 1) < 0.2


def test_depth_noise_grows_with_the_square_of_depth():
    model = REALISTIC.depth
    stds = []
    for z in (0.2, 0.4):
        plate = grid_points(np.full((128, 128), z, np.float32), K)
        out, _ = apply_stereo(
            plate, np.ones((128, 128), bool), model, np.random.default_rng(1), 1 / K[0, 0]
        )
        stds.append(out[2:-2, 2:-2, 2].std())
    assert 3.0 < stds[1] / stds[0] < 5.0  # (0.4 / 0.2)^2 = 4


def test_points_at_a_depth_discontinuity_follow_the_edge_model():
    """A step from 0.20 m (left half) to 0.30 m: pixels at the step are dropped with the
    profile's probability or fly between the two sides; no pixel off the step is."""
    model = REALISTIC.depth
    depth = np.full((128, 128), 0.30, np.float32)
    depth[:, :64] = 0.20
    pts = grid_points(depth, K)
    valid = np.ones(depth.shape, bool)
    edge = edge_mask(depth, valid, discontinuity_jump(depth, model, 1 / K[0, 0]))
    assert edge[:, 63:65].all() and edge.sum() == 2 * 128
    drops, flying = [], []
    for seed in range(20):
        out, ok = apply_stereo(pts, valid, model, np.random.default_rng(seed), 1 / K[0, 0])
        z = out[..., 2]
        assert ok[:, :62].all() and ok[:, 66:].all()  # off the step: never dropped
        assert np.abs(z[:, 5:60] - 0.20).max() < 0.003 and np.abs(z[:, 68:] - 0.30).max() < 0.005
        at = edge
        drops.append((~ok & at).sum() / at.sum())
        between = ok & at & (z > 0.205) & (z < 0.29)
        flying.append(between.sum() / at.sum())
    assert abs(np.mean(drops) - model.edge_dropout) < 0.05
    # A flying pixel's depth is uniform between the sides: most land clear of both.
    assert 0.6 * model.edge_flying < np.mean(flying) <= model.edge_flying + 0.03


def test_grazing_surfaces_return_nothing():
    """A plane seen at 80 deg from its normal returns nothing; at 30 deg everything."""
    model = REALISTIC.depth
    v, u = np.mgrid[0:128, 0:128].astype(np.float64) + 0.5
    rays = np.stack([(u - 64) / 91.4, (v - 64) / 91.4, np.ones_like(u)], axis=-1)
    for angle, returns in ((30, True), (80, False)):
        n = np.array([np.sin(np.radians(angle)), 0.0, -np.cos(np.radians(angle))])
        # the plane n . p = -0.3 through (0, 0, 0.3 / cos)
        t = -0.3 / (rays @ n)
        pts = (rays * t[..., None]).astype(np.float32)
        _, ok = apply_stereo(pts, t > 0, model, np.random.default_rng(0), 1 / K[0, 0])
        centre = ok[54:74, 54:74]
        assert centre.all() if returns else not centre.any(), angle


# ------------------------------------------------------------------ hand-eye


def test_mount_error_has_the_stated_size():
    rng = np.random.default_rng(3)
    for _ in range(5):
        E = mount_error(0.0015, 0.5, rng)
        assert np.isclose(np.linalg.norm(E[:3, 3]), 0.0015)
        assert np.isclose(np.degrees(G.rot_angle(E[:3, :3])), 0.5)


def test_hand_eye_error_moves_the_cloud_rigidly_by_the_stated_amount(make_env, tmp_path):
    """With only a hand-eye error (exact depth): the reported cloud is the true one moved
    by one rigid transform; the camera pose the robot reports is off the true one by
    exactly 1.5 mm and 0.5 deg; the true-frame table is flat at z = 0, the reported one
    is not; and the depth image comes from the (physically) moved camera."""
    hand_eye = _profile_file(
        tmp_path,
        "handeye_only",
        depth={"model": "iid", "std": 0.0},
        hand_eye={"translation": 0.0015, "rotation_deg": 0.5},
    )
    exact = _profile_file(tmp_path, "exact", depth={"model": "iid", "std": 0.0})
    env = make_env("PegInsert6DoF-v1", obs_mode="pointcloud", sensor=str(hand_eye))
    u = env.unwrapped
    obs, _ = env.reset(seed=11)
    true_cam = u.scene.sensors[CAMERA_UID].get_params()["cam2world_gl"][0].numpy()
    told = obs["sensor_param"][CAMERA_UID]["cam2world_gl"][0].numpy()
    off = G.inv(true_cam.astype(np.float64)) @ told.astype(np.float64)
    assert np.isclose(np.linalg.norm(told[:3, 3] - true_cam[:3, 3]), 0.0015, atol=2e-5)
    assert np.isclose(np.degrees(G.rot_angle(off[:3, :3])), 0.5, atol=0.01)
    # The believed camera is where the nominal mount puts it (forward kinematics).
    nominal = u.flange_matrix() @ G.to_matrix(camera_pose_in_tool()) @ SAPIEN_CAM_TO_GL
    np.testing.assert_allclose(told, nominal, atol=1e-5)
    x = obs["pointcloud"]["xyzw"][0].numpy().astype(np.float64)
    pts = x[x[:, 3] > 0, :3]
    M = told @ G.inv(true_cam.astype(np.float64))  # true world -> reported world
    true_pts = (pts - M[:3, 3]) @ M[:3, :3]
    table_true = true_pts[np.abs(true_pts[:, 2]) < 0.003]
    assert len(table_true) > 1000 and np.abs(table_true[:, 2]).max() < 0.0015
    near = pts[np.abs(pts[:, 2]) < 0.02]
    A = np.column_stack([near[:, 0], near[:, 1], np.ones(len(near))])
    (a, b, _), *_ = np.linalg.lstsq(A, near[:, 2], rcond=None)
    assert np.degrees(np.arctan(np.hypot(a, b))) > 0.02  # the reported table is tilted
    # Depth images come from the moved camera: they differ from the exact sensor's.
    env_img = make_env("PegInsert6DoF-v1", obs_mode="rgbd", sensor=str(hand_eye))
    env_ref = make_env("PegInsert6DoF-v1", obs_mode="rgbd", sensor=str(exact))
    a_img = env_img.reset(seed=11)[0]["sensor_data"][CAMERA_UID]["depth"]
    b_img = env_ref.reset(seed=11)[0]["sensor_data"][CAMERA_UID]["depth"]
    assert (a_img != b_img).float().mean() > 0.05


# ------------------------------------------------------------------ wrist wrench


def _press_on_rim(env, seed: int) -> None:
    """The peg 8 mm off the hole's axis, pushed down onto its rim (position control, no
    search): a steady contact."""
    u = env.unwrapped
    env.reset(seed=seed)
    ex = Executor(env, ExecutorConfig(insertion="position", search_radius=0.0))
    ex.reset()
    P = u.insertion_pose(-PRE_INSERT_HEIGHT)
    P[:3, 3] += 0.008 * P[:3, 0]
    assert ex.move_to(P).ok
    ex.insert(u.task.hole_depth + PRE_INSERT_HEIGHT, entry=PRE_INSERT_HEIGHT)


@pytest.mark.parametrize("sensor", ["ideal", "realistic"])
def test_wrist_wrench_is_the_summed_contact_wrench_within_the_noise(make_env, sensor):
    env = make_env("PegInsert6DoF-v1", obs_mode="state", sensor=sensor)
    u = env.unwrapped
    _press_on_rim(env, seed=4)
    force, moment = u.contact_wrench()
    assert np.linalg.norm(force) > 5.0  # it is pressing
    R = u.flange_matrix()[:3, :3]
    truth = np.concatenate([R.T @ force, R.T @ moment])
    reading = u.wrist_wrench()
    assert reading.shape == (6,)  # one wrench: nothing per contact
    w = u.sensor_profile.wrench
    if sensor == "ideal":
        np.testing.assert_allclose(reading, truth, atol=1e-9)
        return
    err = reading - truth - u.sensing.wrench_bias
    assert np.all(np.abs(err[:3]) < 5 * w.force_noise) and np.all(
        np.abs(err[3:]) < 5 * w.torque_noise
    )
    # The noise over many control steps has the profile's spread.
    samples = np.array([u.sensing.wrench_error(k) for k in range(400)]) - u.sensing.wrench_bias
    assert abs(samples[:, :3].std() / w.force_noise - 1) < 0.2
    assert abs(samples[:, 3:].std() / w.torque_noise - 1) < 0.2


# ------------------------------------------------------------------ profiles


def test_shipped_profiles_load_and_cite_their_numbers():
    assert {"ideal", "realistic"} <= set(available_profiles())
    for name in available_profiles():
        p = load_profile(name)
        assert p.sources, f"{name}: no sources"
    assert load_profile("ideal").depth.model == "iid"
    assert REALISTIC.depth.model == "stereo" and REALISTIC.hand_eye.translation > 0
    assert load_profile(str(resources.bundled("sensors") / "realistic.yaml")) == REALISTIC


@pytest.mark.parametrize(
    "sections, field",
    [
        (
            {"depth": {"model": "stereo", "focal_px": 400, "baseline": 0.02, "noise": 1}},
            "depth.noise",
        ),
        ({"depth": {"model": "tof"}}, "depth.model"),
        ({"depth": {"model": "stereo"}}, "depth.focal_px"),
        ({"hand_eye": {"translation": -0.001}}, "hand_eye.translation"),
        ({"wrench": {"force_noise": "lots"}}, "wrench.force_noise"),
        ({"depth": {"edge_dropout": 0.8, "edge_flying": 0.5}}, "depth.edge_flying"),
        ({"camera": {}}, "camera"),
        ({"imager": {"stereo_baseline": 0}}, "imager.stereo_baseline"),
    ],
)
def test_bad_profile_fields_are_named(tmp_path, sections, field):
    path = _profile_file(tmp_path, "bad", **sections)
    with pytest.raises(SensorProfileError, match=f"bad.yaml: field '{field}'") as e:
        load_profile(str(path))
    # eval workers raise it in another process: it must arrive with its message intact
    assert str(pickle.loads(pickle.dumps(e.value))) == str(e.value)


def test_unknown_sensor_exits_2_listing_the_profiles(tmp_path):
    for args in (
        ("cfvs_maniskill.run", "--sensor", "nosuch"),
        ("cfvs_maniskill.eval", "--sensors", "ideal", "nosuch", "--out", str(tmp_path)),
        ("cfvs_maniskill.data", "collect", "--sensor", "nosuch", "--out", str(tmp_path / "x.h5")),
    ):
        r = run_cli(*args)
        assert r.returncode == 2, (args, r.stderr[-500:])
        assert "unknown sensor profile 'nosuch'" in r.stderr
        assert all(name in r.stderr for name in available_profiles())
    assert not (tmp_path / "episodes.jsonl").exists()  # nothing was started


@pytest.mark.parametrize("obs_mode", ["rgbd", "pointcloud"])
def test_realistic_observations_round_trip_through_the_state(make_env, obs_mode):
    """Save in episode A, reset into B, restore A: the realistic sensor's readings (noise,
    edges, hand-eye error, camera mount) are A's again. A restored state is the same state
    every time, so two restorations read the same images to the last bit. Against the
    reading before the save they agree but for the pixels a last-bit change moves: PhysX
    restores link poses to the last bit only (the arm's pose from its joints, not from the
    integration), a silhouette pixel can flip, and the stereo model's edge, incidence and
    occlusion tests spread it to neighbours (0-1.6% of the points, measured), whereas a
    noise stream or mount not restored changes nearly every point."""
    from mani_skill.utils import common

    from tests.test_maniskill_conformance import assert_obs_equal

    env = make_env("PegInsert6DoF-v1", obs_mode=obs_mode, sensor="realistic")
    u = env.unwrapped
    env.reset(seed=7, options={"object": "cylinder"})
    env.step(env.action_space.sample())
    state = u.get_state_dict()
    obs, mount, bias = u.get_obs(), u.sensing.mount.copy(), u.sensing.wrench_bias.copy()
    restored = []
    for _ in range(2):
        env.reset(seed=8, options={"object": "cuboid_test_2"})
        assert not np.array_equal(mount, u.sensing.mount)
        u.set_state_dict(state)
        np.testing.assert_array_equal(mount, u.sensing.mount)
        np.testing.assert_array_equal(bias, u.sensing.wrench_bias)
        restored.append(common.flatten_dict_keys(common.to_numpy(u.get_obs())))
    first, again = restored
    assert first.keys() == again.keys()
    for key in first:
        np.testing.assert_array_equal(first[key], again[key], err_msg=key)
    images = {"pointcloud/xyzw", "sensor_data/wrist_camera/depth"}
    a = common.flatten_dict_keys(common.to_numpy(obs))
    b = dict(first)
    for key in images & a.keys():
        x, y = a.pop(key), b.pop(key)
        differ = ~np.isclose(x.astype(np.float64), y.astype(np.float64), rtol=0, atol=1e-6)
        assert differ.reshape(-1, x.shape[-1]).any(-1).mean() <= 0.1, key
    assert_obs_equal(a, b)


@pytest.mark.parametrize("noise", [0.001, 0.003])
def test_table_removal_follows_the_measured_noise(noise):
    """A table tilted 0.5 deg and raised 2 mm (a hand-eye error) with `noise` of depth
    noise, and a box standing on it: the fitted plane and noise are recovered, the table
    is removed whole, the box above the margin kept (a fixed 6 mm cut leaked the table at
    3 mm of noise)."""
    from cfvs_maniskill.perception.clouds import fit_table

    rng = np.random.default_rng(0)
    xy = rng.uniform([0.3, -0.2], [0.7, 0.2], size=(20000, 2))
    tilt = np.radians(0.5)
    table = np.column_stack([xy, 0.002 + np.tan(tilt) * (xy[:, 0] - 0.5)])
    table[:, 2] += rng.normal(0, noise, len(table))
    box = np.column_stack([rng.uniform(0.45, 0.55, (3000, 2)), rng.uniform(0.0, 0.08, 3000)])
    fit = fit_table(np.vstack([table, box]).astype(np.float32))
    assert abs(fit.sigma / noise - 1) < 0.2
    assert np.degrees(np.arccos(fit.normal[2])) == pytest.approx(0.5, abs=0.1)
    assert (fit.height(table) > fit.margin).mean() < 1e-3
    kept = fit.height(box) > fit.margin
    assert kept[box[:, 2] > 0.002 + 8 * noise + 0.003].all()


def test_hand_eye_floor_is_the_mount_error_seen_at_the_hole():
    """The residual a perfect hole estimator leaves under a mount error: none without one,
    a translation's part across the tool axis, a turn's angle as tilt, and never more than
    the translation plus the turn times the camera's distance to the hole."""
    assert np.allclose(hand_eye_residual(np.eye(4)), (0.0, 0.0), atol=1e-9)
    C = camera_in_tip()
    t = np.array([0.001, -0.0005, 0.002])  # in the camera's frame
    along = C[:3, :3] @ t  # in the tip frame
    lateral, tilt = hand_eye_residual(G.make(np.eye(3), t))
    assert lateral == pytest.approx(np.linalg.norm(along[:2]), abs=1e-9) and tilt < 1e-6
    # A turn about the camera's centre by 1 deg about an axis across the tool's z.
    axis = np.linalg.solve(C[:3, :3], np.array([1.0, 0.0, 0.0]))
    R = Rotation.from_rotvec(np.radians(1.0) * axis).as_matrix()
    assert hand_eye_residual(G.make(R, np.zeros(3)))[1] == pytest.approx(1.0, abs=1e-6)
    lever = np.linalg.norm(pre_insertion_hole()[:3, 3] - C[:3, 3])
    s = floor_samples(0.0015, 0.5, 500, seed=1)
    assert np.all(s[:, 0] <= 0.0015 + np.radians(0.5) * lever + 1e-9)
    assert np.all(s[:, 1] <= 0.5 + 1e-6) and s[:, 0].max() > 0.0015


def test_closing_the_loop_on_the_peg_removes_the_calibration_floor():
    """A camera that sees the peg and the opening and servoes their offset: without noise
    no mount or camera-calibration error leaves a residual (a linear camera error keeps
    the tip on the axis); with the profile's noise it stays far below the open-loop floor."""
    from cfvs_maniskill.sensing.floor import closed_loop_samples, profile_floor_samples

    for name in ("realistic", "handeye_2mm_1deg"):
        profile = load_profile(name)
        exact = closed_loop_samples(profile, 300, seed=2, points=10**12)
        assert np.percentile(exact[:, 0], 90) < 1e-5 and np.percentile(exact[:, 1], 90) < 1e-3
        open_loop = profile_floor_samples(profile, 300, seed=2)
        assert np.percentile(open_loop[:, 0], 90) > 1.5e-3
    noisy = closed_loop_samples(load_profile("realistic"), 2000, seed=2)
    assert 1e-5 < np.percentile(noisy[:, 0], 90) < 0.5e-3


def test_a_remembered_table_fit_is_the_fit_of_that_cloud_and_threshold():
    """fit_table remembers recent fits (the calibration and the planner fit the same raw
    view): a cloud with 1000 table points is too few at min_points=2000 (the nominal
    table) but a fit at 200, whichever is asked first; a changed cloud is fitted anew."""
    from cfvs_maniskill.perception.clouds import NOMINAL_TABLE, _fit_table, fit_table

    rng = np.random.default_rng(1)
    xy = rng.uniform(0.3, 0.7, size=(1000, 2))
    cloud = np.column_stack([xy, 0.003 + rng.normal(0, 0.001, 1000)]).astype(np.float32)
    for first, second in ((2000, 200), (200, 2000)):
        for m in (first, second, first):
            fit, fresh = fit_table(cloud, min_points=m), _fit_table(cloud, m)[0]
            assert np.array_equal(fit.normal, fresh.normal)
            assert (fit.offset, fit.sigma) == (fresh.offset, fresh.sigma)
            assert (fit is NOMINAL_TABLE) == (m == 2000)
        cloud = cloud.copy()
    moved = cloud + np.float32([0, 0, 0.004])
    assert fit_table(moved).offset == pytest.approx(fit_table(cloud).offset + 0.004, abs=2e-4)
