"""The wrist camera's stereo imagers (gym.make(..., stereo=True)), the images KOVIS sees:
where they are, what they show, and that the sensor profile sets their baseline."""

from __future__ import annotations

import numpy as np
import pytest

from cfvs_maniskill.perception.images import stereo_images
from cfvs_maniskill.robots.ur5 import CAMERA_UID, STEREO_UIDS
from cfvs_maniskill.sensing.profile import load_profile


def _cam2world(obs: dict, uid: str) -> np.ndarray:
    return obs["sensor_param"][uid]["cam2world_gl"][0].numpy().astype(np.float64)


@pytest.mark.parametrize("sensor", ["ideal", "realistic", "handeye_2mm_1deg"])
def test_imagers_sit_one_profile_baseline_apart_on_the_true_camera(make_env, sensor):
    """The left imager is the wrist camera itself (where its possibly miscalibrated mount
    really holds it); the right one is the profile's baseline along the image's x axis."""
    env = make_env("PegInsert3DoF-v1", obs_mode="rgbd", stereo=True, sensor=sensor)
    obs, _ = env.reset(seed=4)
    u = env.unwrapped
    left, right = (_cam2world(obs, uid) for uid in STEREO_UIDS)
    true_cam = u.scene.sensors[CAMERA_UID].camera.get_model_matrix()
    assert np.allclose(left, true_cam, atol=1e-5)
    offset = np.linalg.inv(left) @ right  # right imager in the left one's (OpenGL) frame
    baseline = load_profile(sensor).imager.stereo_baseline
    assert np.allclose(offset[:3, 3], [baseline, 0, 0], atol=1e-5)
    assert np.allclose(offset[:3, :3], np.eye(3), atol=1e-6)


def test_imagers_see_the_hole_from_two_viewpoints(make_env):
    """Lit grey images (the hole's opening shades darker than its face), and the same
    scene shifted between the two imagers."""
    env = make_env("PegInsert3DoF-v1", obs_mode="rgbd", stereo=True, objects=("test",))
    obs, _ = env.reset(seed=2)
    pair = stereo_images(obs).astype(float)
    assert pair.shape == (2, 96, 96)
    assert pair[0].std() > 10  # shading, not one flat colour per face
    assert 1.0 < np.abs(pair[0] - pair[1]).mean() < 40


def test_stereo_is_refused_for_point_clouds():
    import gymnasium as gym

    with pytest.raises(ValueError, match="stereo=True.*pointcloud"):
        gym.make("PegInsert3DoF-v1", obs_mode="pointcloud", stereo=True)
