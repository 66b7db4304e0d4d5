"""The stereo camera's effects one by one: texture-driven dropouts and noise (plain vs
textured, passive vs projector), one-sided occlusion along the baseline, the fixed
pattern, the per-episode depth bias and intrinsics error, the D405's field of view, and
the floor those errors put under any camera-only agent."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.special import ndtr

from cfvs_maniskill.objects.spec import HoleSpecError, parse_spec
from cfvs_maniskill.sensing import surfaces
from cfvs_maniskill.sensing.depth import EpisodeDepth, apply_stereo, grid_points, occluded
from cfvs_maniskill.sensing.floor import (
    depth_residuals,
    hand_eye_residuals,
    profile_floor_samples,
    table_calibrations,
)
from cfvs_maniskill.sensing.model import SensorModel, mount_errors
from cfvs_maniskill.sensing.profile import load_profile

REALISTIC = load_profile("realistic")
D435 = load_profile("d435")
K = np.array([[91.4, 0.0, 64.0], [0.0, 91.4, 64.0], [0.0, 0.0, 1.0]])
SIZE = (128, 128)


def _plate(z: float) -> np.ndarray:
    return grid_points(np.full(SIZE, z, np.float32), K)


def _episode(seed: int = 0, **kw) -> EpisodeDepth:
    rng = np.random.default_rng(seed)
    return EpisodeDepth(
        fixed_noise=rng.standard_normal(SIZE, dtype=np.float32),
        fixed_uniform=rng.random(SIZE, dtype=np.float32),
        **kw,
    )


def _surface(albedo: float, material: str) -> tuple[np.ndarray, np.ndarray]:
    c = surfaces.MATERIALS[material]
    return np.full(SIZE, albedo, np.float32), np.full(SIZE, c, np.float32)


def _observe(model, z, surface, episode, seed=0):
    return apply_stereo(
        _plate(z), np.ones(SIZE, bool), model, np.random.default_rng(seed), 1 / K[0, 0],
        surface, episode,
    )  # fmt: skip


def test_plain_parts_drop_pixels_and_textured_ones_do_not():
    """A plate square-on at 15 cm: a plain mid-grey part returns the share the matching
    curve predicts (about 3/5) with 2.5x the noise; a printed one returns every pixel at
    the textured noise; a dark plain part returns few."""
    d = REALISTIC.depth
    p = _plate(0.15)[2:-2, 2:-2]
    cos_inc = p[..., 2] / np.linalg.norm(p, axis=-1)  # the plate is seen along each ray
    fills, stds = {}, {}
    for name, albedo, material in (
        ("plain", 0.6, "plain"),
        ("printed", 0.6, "printed"),
        ("dark", 0.15, "plain"),
    ):
        out, ok = _observe(d, 0.15, _surface(albedo, material), _episode())
        inner = ok[2:-2, 2:-2]
        fills[name] = inner.mean()
        stds[name] = out[2:-2, 2:-2, 2][inner].std() if inner.any() else np.nan
        snr = albedo * surfaces.MATERIALS[material] * cos_inc / d.imager_noise
        want = ndtr(np.log(snr / d.texture_fill_snr) / d.texture_fill_spread).mean()
        assert abs(fills[name] - want) < 0.03, (name, fills[name], want)
    assert fills["printed"] > 0.99 and 0.45 < fills["plain"] < 0.75 and fills["dark"] < 0.05
    assert 2.0 < stds["plain"] / stds["printed"] < 3.2


def test_a_projector_makes_plain_parts_return():
    """The D435's pattern gives a plain face texture: nearly every pixel returns."""
    _, ok = _observe(D435.depth, 0.2, _surface(0.6, "plain"), _episode())
    assert ok[2:-2, 2:-2].mean() > 0.99


def test_grazing_views_of_texture_match_worse():
    """The same plain part seen at 60 deg returns fewer pixels than square-on."""
    d = REALISTIC.depth
    v, u = np.mgrid[0:128, 0:128].astype(np.float64) + 0.5
    rays = np.stack([(u - 64) / K[0, 0], (v - 64) / K[1, 1], np.ones_like(u)], axis=-1)
    fills = []
    for angle in (0, 60):
        n = np.array([np.sin(np.radians(angle)), 0.0, -np.cos(np.radians(angle))])
        pts = (rays * (-0.15 / (rays @ n))[..., None]).astype(np.float32)
        _, ok = apply_stereo(
            pts, np.ones(SIZE, bool), d, np.random.default_rng(0), 1 / K[0, 0],
            _surface(0.6, "plain"), _episode(),
        )  # fmt: skip
        fills.append(ok[40:88, 40:88].mean())
    assert fills[1] < fills[0] - 0.3


def test_occlusion_is_one_sided_along_the_baseline():
    """A near block (0.15 m) in the middle of a far wall (0.30 m): the right imager (at +x)
    cannot see a band f B (1/0.15 - 1/0.30) wide just left of the block; right of it and
    above and below it, everything is seen."""
    z = np.full(SIZE, 0.30, np.float32)
    z[40:88, 50:80] = 0.15
    f, B = K[0, 0], 0.018
    hidden = occluded(z, np.ones(SIZE, bool), f, B)
    width = f * B * (1 / 0.15 - 1 / 0.30)  # 5.5 px
    band = hidden[40:88]
    cols = np.nonzero(band.any(axis=0))[0]
    assert cols.max() < 50 and cols.min() >= 50 - int(np.ceil(width)) - 1
    assert abs(band.sum(axis=1).mean() - width) <= 1.0
    assert not hidden[:, 80:].any() and not hidden[:40].any() and not hidden[88:].any()
    # In the model: the band returns nothing, the block's other side does.
    pts = grid_points(z, K)
    _, ok = apply_stereo(pts, np.ones(SIZE, bool), REALISTIC.depth, np.random.default_rng(0),
                         1 / f)  # fmt: skip
    assert not ok[hidden].any() and ok[45:83, 83:120].all()


def test_fixed_pattern_repeats_between_observations():
    """Two observations of a static plate: the fixed share of the disparity noise repeats
    (their errors correlate by `fixed_pattern`), a fresh episode's pattern does not; with
    the whole noise fixed, the depths are identical."""
    d = dataclasses.replace(REALISTIC.depth, lateral_noise_px=0.0, disparity_step_px=0.0,
                            depth_unit=0.0)  # fmt: skip
    z = 0.3
    a, _ = _observe(d, z, None, _episode(1), seed=10)
    b, _ = _observe(d, z, None, _episode(1), seed=11)
    c, _ = _observe(d, z, None, _episode(2), seed=12)
    ea, eb, ec = (x[2:-2, 2:-2, 2].ravel() - z for x in (a, b, c))
    assert abs(np.corrcoef(ea, eb)[0, 1] - d.fixed_pattern) < 0.05
    assert abs(np.corrcoef(ea, ec)[0, 1]) < 0.05
    whole = dataclasses.replace(d, fixed_pattern=1.0)
    a, _ = _observe(whole, z, None, _episode(1), seed=10)
    b, _ = _observe(whole, z, None, _episode(1), seed=11)
    assert np.array_equal(a[..., 2], b[..., 2])


def test_depth_bias_and_intrinsics_errors_stay_within_their_bounds():
    """Per episode: the depth scale within 1 +- depth_scale_error and filling most of it,
    the focal and principal-point errors within theirs; a plate's mean depth is the true
    one times the scale; the reported intrinsics say the error, and the cloud is formed
    with them (the plate's points move across by the principal-point error)."""
    model = SensorModel(REALISTIC, 0.0)
    d = REALISTIC.depth
    scales, ratios, pps = [], [], []
    for seed in range(300):
        model.start_episode(seed)
        e = model.depth_errors
        scales.append(e.scale)
        ratios.append(e.focal_ratio)
        pps.append(e.principal_offset)
    scales, ratios, pps = np.array(scales), np.array(ratios), np.abs(np.array(pps))
    assert np.all(np.abs(scales - 1) <= d.depth_scale_error)
    assert np.abs(scales - 1).max() > 0.9 * d.depth_scale_error
    assert np.all(np.abs(1 / ratios - 1) <= d.focal_error + 1e-12)
    assert (
        np.all(pps <= d.principal_point_error_px) and pps.max() > 0.9 * d.principal_point_error_px
    )
    clean = dataclasses.replace(d, lateral_noise_px=0.0, disparity_noise_px=0.0)
    ep = _episode(scale=1.015, principal_offset=(0.8, 0.0))
    out, ok = _observe(clean, 0.2, None, ep)
    assert np.median(out[ok][:, 2]) == pytest.approx(0.2 * 1.015, abs=2e-4)
    shift = out[..., 0] / out[..., 2] - _plate(0.2)[..., 0] / 0.2
    assert np.median(shift[ok]) == pytest.approx(0.8 / d.focal_px, rel=1e-3)
    model.start_episode(7)
    Kr = model.reported_intrinsic(K)
    e = model.depth_errors
    assert Kr[0, 0] == pytest.approx(K[0, 0] / e.focal_ratio)
    assert Kr[0, 2] == pytest.approx(K[0, 2] - e.principal_offset[0] * K[0, 0] / d.focal_px)


def test_the_floor_adds_the_depth_cameras_errors():
    """Without depth errors the floor is the hand-eye one exactly; a 2% depth scale alone
    puts the hole off by the lateral part of 2% of its oblique ray (over a millimetre at
    the pre-insertion view), and the realistic profile's floor is above its hand-eye
    part."""
    n = 200
    mounts = mount_errors(0.0015, 0.5, np.random.default_rng(0), n)
    none = dict(
        scale=np.ones(n), offset=np.zeros(n), focal_ratio=np.ones(n), principal=np.zeros((n, 2))
    )
    assert np.allclose(depth_residuals(mounts, none, 447.0), hand_eye_residuals(mounts))
    eye = np.tile(np.eye(4), (n, 1, 1))
    scaled = dict(none, scale=np.full(n, 1.02))
    lateral = depth_residuals(eye, scaled, 447.0)[:, 0]
    assert np.allclose(lateral, lateral[0]) and 0.001 < lateral[0] < 0.003
    full = profile_floor_samples(REALISTIC, 2000, seed=0)
    hand_eye = hand_eye_residuals(mount_errors(0.0015, 0.5, np.random.default_rng(0), 2000))
    assert np.percentile(full[:, 0], 90) > np.percentile(hand_eye[:, 0], 90) + 0.0003


def test_the_table_calibration_takes_the_depth_scale_and_the_tilt_out_of_the_floor():
    """Calibrated against the table, a pure depth-scale error leaves nothing; a mount turn
    about axes across the (vertical) tool leaves no tilt; with the realistic profile's
    errors the floor's p90 falls, but not below what the table cannot see (the hand-eye
    translation)."""
    n = 50
    none = dict(
        scale=np.ones(n), offset=np.zeros(n), focal_ratio=np.ones(n), principal=np.zeros((n, 2))
    )
    eye = np.tile(np.eye(4), (n, 1, 1))
    assert np.allclose(table_calibrations(eye, none, 447.0, 0.27), np.eye(3), atol=1e-9)
    scaled = dict(none, scale=np.linspace(0.98, 1.02, n))
    K = table_calibrations(eye, scaled, 447.0, 0.27)
    assert depth_residuals(eye, scaled, 447.0)[:, 0].max() > 0.001
    assert depth_residuals(eye, scaled, 447.0, K)[:, 0].max() < 1e-6
    turns = mount_errors(0.0, 1.0, np.random.default_rng(1), n)
    assert hand_eye_residuals(turns)[:, 1].max() > 0.5
    assert (
        depth_residuals(turns, none, 447.0, table_calibrations(turns, none, 447.0, 0.27))[
            :, 1
        ].max()
        < 1e-3
    )
    trusting = profile_floor_samples(REALISTIC, 2000, seed=0)
    calibrated = profile_floor_samples(REALISTIC, 2000, seed=0, table_height=0.27)
    translation = hand_eye_residuals(mount_errors(0.0015, 0.0, np.random.default_rng(0), 2000))
    p90 = [np.percentile(x[:, 0], 90) for x in (trusting, calibrated, translation)]
    assert p90[0] - 0.0005 > p90[1] > p90[2]


def test_realistic_camera_has_the_d405_field_of_view(make_env):
    """The wrist camera renders 87 x 58 deg at the task's angular resolution, square
    pixels; the observation reports the episode's intrinsics error; two observations of
    the same scene drop the same plain-part pixels (the fill is fixed per episode)."""
    env = make_env("PegInsert6DoF-v1", obs_mode="pointcloud", sensor="realistic")
    obs, _ = env.reset(seed=4)
    u = env.unwrapped
    w, h, fovy = u.camera_geometry
    assert (w, h) == (173, 101) and np.degrees(fovy) == pytest.approx(58.0, abs=0.6)
    f_true = (h / 2) / np.tan(fovy / 2)
    K_rep = obs["sensor_param"]["wrist_camera"]["intrinsic_cv"][0].numpy()
    assert K_rep[0, 0] == pytest.approx(f_true / u.sensing.depth_errors.focal_ratio, rel=1e-4)
    assert K_rep[0, 0] == pytest.approx(K_rep[1, 1])
    seg = obs["pointcloud"]["segmentation"][0, :, 0].numpy()
    part = seg == int(u.hole_objects[u.object_index].per_scene_id[0])
    first = obs["pointcloud"]["xyzw"][0, :, 3].numpy() > 0
    again = u.get_obs()["pointcloud"]["xyzw"][0, :, 3].numpy() > 0
    assert part.sum() > 500 and 0.1 < first[part].mean() < 0.95
    assert (first[part] == again[part]).mean() > 0.97  # edges' draws are per observation


def test_hole_files_name_their_material(tmp_path):
    f = tmp_path / "x.yaml"
    base = {"body": {"box": {"size": [0.1, 0.1, 0.05]}}}
    assert parse_spec(base, f).texture_contrast == surfaces.MATERIALS["plain"]
    assert parse_spec({**base, "material": "printed"}, f).texture_contrast == 0.2
    assert parse_spec({**base, "material": "plain", "texture": 0.05}, f).texture_contrast == 0.05
    with pytest.raises(HoleSpecError) as e:
        parse_spec({**base, "material": "velvet"}, f)
    assert "material" in str(e.value) and "printed" in str(e.value)
    with pytest.raises(HoleSpecError) as e:
        parse_spec({**base, "texture": 2.0}, f)
    assert "texture" in str(e.value)


def test_the_docs_noise_table_is_what_the_code_gives():
    from cfvs_maniskill.report.sensing_figures import DOC, MARK, table

    doc = DOC.read_text()
    assert f"<!-- report:{MARK} begin -->\n{table()}\n<!-- report:{MARK} end -->" in doc, (
        "run `python -m cfvs_maniskill.report.sensing_figures` to rewrite docs/sensing.md"
    )
