"""Episode videos (`rendering/film.py`): a filmed episode is the episode that was scored,
and its frames are pictures a person can read (size, views, captions)."""

from __future__ import annotations

import numpy as np
import pytest

from cfvs_maniskill.control.executor import Executor, ExecutorConfig
from cfvs_maniskill.episode import run_episode
from cfvs_maniskill.policies.registry import make_agent
from cfvs_maniskill.rendering.film import CAPTION_PX, Film, project
from cfvs_maniskill.rendering.views import CLOSEUP_PX, look_at


def _record(r) -> dict:
    d = r.to_json()
    d.pop("wall_time_s")
    return d


@pytest.mark.slow
def test_filming_does_not_change_the_episode(make_env, tmp_path):
    env = make_env("PegInsert6DoF-v1", obs_mode="pointcloud", sensor="realistic")
    agent = make_agent("cfvs", env)
    executor = Executor(env, ExecutorConfig())
    plain = run_episode(env, agent, executor, seed=11)
    film = Film(env, "cfvs")
    filmed = run_episode(env, agent, executor, seed=11, film=film)
    # Same seed, noisy sensor: equal only if the film drew nothing from the sensing streams.
    assert _record(filmed) == _record(plain)

    frames = np.stack(film.frames)
    assert frames.shape[1:] == (CLOSEUP_PX + CAPTION_PX, CLOSEUP_PX * 3 // 2, 3)
    close = frames[:, :CLOSEUP_PX, :CLOSEUP_PX].astype(np.float64)
    assert close.std() > 10  # a shaded scene, not one flat colour
    assert np.abs(close[0] - close[-1]).mean() > 1  # the peg moved into view
    caption = frames[:, CLOSEUP_PX:]
    assert (caption > 200).any(axis=(1, 2, 3)).all()  # white text on every frame
    assert film.captions[0].startswith("coarse")
    assert any(c.startswith("fine iteration 1") for c in film.captions)
    assert any(c.startswith("insertion") for c in film.captions)
    assert film.captions[-1] == ("success" if filmed.success else f"failure: {filmed.reason}")

    path = film.write(tmp_path / "episode.mp4")
    import imageio.v2 as imageio

    with imageio.get_reader(path) as reader:
        first = reader.get_data(0)
        n = reader.count_frames()
    assert first.shape[0] >= 512 and n == len(film.frames)


@pytest.mark.slow
def test_a_tight_fit_film_names_the_force_phases(make_env):
    env = make_env("PegInsert6DoF-1mm-v1", obs_mode="pointcloud")
    film = Film(env, "oracle")
    agent = make_agent("oracle", env)
    run_episode(env, agent, Executor(env, ExecutorConfig()), seed=2, film=film)
    assert any(c.startswith("insertion (force)") for c in film.captions)


def test_projection_puts_a_point_on_the_optical_axis_at_the_principal_point():
    K = np.array([[100.0, 0, 64], [0, 100.0, 48], [0, 0, 1]])
    ext = np.hstack([np.eye(3), np.zeros((3, 1))])  # camera at the origin, looking along +z
    uv = project(
        np.array([[0.0, 0.0, 2.0], [0.1, 0.0, 1.0], [0.0, 0.0, -1.0]]),
        {"extrinsic_cv": ext, "intrinsic_cv": K},
    )
    assert np.allclose(uv[0], [64, 48]) and np.allclose(uv[1], [74, 48])
    assert np.isnan(uv[2]).all()  # behind the camera: not drawn


def test_look_at_gives_maniskills_camera_pose():
    from mani_skill.utils import sapien_utils

    rng = np.random.default_rng(3)
    for _ in range(50):
        eye, target = rng.normal(size=3), rng.normal(size=3)
        ours, theirs = look_at(eye, target), sapien_utils.look_at(eye=eye, target=target).sp
        assert np.allclose(ours.p, theirs.p, atol=1e-6)
        q, r = np.asarray(ours.q), np.asarray(theirs.q)
        assert min(np.abs(q - r).max(), np.abs(q + r).max()) < 1e-6  # q and -q: one turn


def test_an_env_without_the_render_cameras_gets_a_clear_error():
    from types import SimpleNamespace

    scene = SimpleNamespace(human_render_cameras={"render_camera": object()})
    env = SimpleNamespace(unwrapped=SimpleNamespace(scene=scene))
    with pytest.raises(ValueError, match="closeup.*overview.*render_camera"):
        Film(env, "cfvs")
