"""The wrist camera's mount (a field of the sensor profile) and the peg measured in the cloud
(perception/peg.py): the camera sits where the profile says, records name the mount, the
rendered cloud is unbiased, and the peg's points give the camera's error back."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from cfvs_maniskill import geometry as G
from cfvs_maniskill.constants import PEG_LENGTH, PRE_INSERT_HEIGHT, peg_half_extent
from cfvs_maniskill.perception.clouds import valid_world_points, world_to_tool
from cfvs_maniskill.perception.peg import MIN_PEG_POINTS, peg_correction
from cfvs_maniskill.policies.interface import TaskSpec
from cfvs_maniskill.robots.mounts import DEFAULT_MOUNT, MOUNTS
from cfvs_maniskill.robots.ur5 import CAMERA_FOV
from cfvs_maniskill.sensing.model import SAPIEN_CAM_TO_GL
from cfvs_maniskill.sensing.profile import SensorProfileError, available_profiles, load_profile


def _profile(tmp_path, name: str, **sections) -> str:
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump({"depth": {"model": "iid", "std": 0.0}, **sections}))
    return str(path)


def test_a_mount_aims_its_optical_axis_at_its_aim():
    for m in MOUNTS.values():
        T = m.in_tool()
        assert np.allclose(T[:3, 3], m.position)
        to_aim = np.subtract(m.aim, m.position)
        assert np.allclose(T[:3, 0], to_aim / np.linalg.norm(to_aim))  # SAPIEN looks along +x
        assert np.isclose(np.linalg.det(T[:3, :3]), 1.0)
    assert np.allclose(MOUNTS[DEFAULT_MOUNT].in_tcp()[:3, 3], [0.11, 0.0, -0.05])


def test_a_profile_names_a_mount_or_describes_its_own(tmp_path):
    assert (
        load_profile(_profile(tmp_path, "a", mount="peg_view")).camera_mount == MOUNTS["peg_view"]
    )
    assert load_profile(_profile(tmp_path, "b")).camera_mount.name == DEFAULT_MOUNT
    own = {
        "name": "bracket",
        "position": [0.1, 0.0, 0.0],
        "aim": [0.0, 0.0, 0.2],
        "source": "drawing 7",
    }
    m = load_profile(_profile(tmp_path, "c", mount=own)).camera_mount
    assert (m.name, m.position, m.source) == ("bracket", (0.1, 0.0, 0.0), "drawing 7")


@pytest.mark.parametrize("sensor", available_profiles())
def test_each_profiles_mount_shows_the_peg_tip_and_the_opening_in_its_range(sensor):
    """The fine stage measures the peg and the opening in one view: on every shipped profile
    whose mount is to see the peg (all but `flange_side`), the peg's last 2 cm and the
    opening at the pre-insertion pose lie within the camera's depth range and field of
    view. (tip_view under the D435's 12.7 cm Min-Z put the whole peg out of range.)"""
    profile = load_profile(sensor)
    mount = profile.camera_mount
    if mount.name == "flange_side":
        return
    d = profile.depth
    fov = d.fov_deg or (np.degrees(CAMERA_FOV),) * 2
    z = np.linspace(PEG_LENGTH - 0.02, PEG_LENGTH, 5)
    # the peg's side towards the camera (+x), its tip's centre, the opening's centre
    side = np.c_[np.full_like(z, peg_half_extent("round")), 0 * z, z]
    points = np.r_[side, [[0.0, 0.0, PEG_LENGTH], [0.0, 0.0, PEG_LENGTH + PRE_INSERT_HEIGHT]]]
    seen = mount.in_view(points, (d.min_range, d.max_range), fov)
    assert seen.all(), f"{sensor}: mount {mount.name} does not show {points[~seen]}"


@pytest.mark.parametrize(
    "mount, field, says",
    [
        ("nosuch", "mount.name", "flange_side"),
        ({"name": "x", "position": [0.1, 0, 0], "aim": [0, 0, 0.2]}, "mount.source", "source"),
        (
            {"name": "x", "position": [0.1, 0, 0], "aim": [0.1, 0, 0], "source": "s"},
            "mount.aim",
            "1 mm",
        ),
        (
            {"name": "peg_view", "position": [0.1, 0, 0], "aim": [0, 0, 0.2], "source": "s"},
            "mount.position",
            "named mount",
        ),
        ({"name": "x", "height": 3}, "mount.height", "unknown key"),
    ],
)
def test_a_bad_mount_is_named(tmp_path, mount, field, says):
    with pytest.raises(SensorProfileError, match=f"bad.yaml: field '{field}'.*{says}"):
        load_profile(_profile(tmp_path, "bad", mount=mount))


def _move(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ T[:3, :3].T + T[:3, 3]


def _square_peg_faces(rng, n: int, faces=("+x", "+y")) -> np.ndarray:
    """Points on the square peg's side faces, the lowest 60 mm (tcp frame)."""
    h = peg_half_extent("square")
    out = []
    for f in faces:
        a = rng.uniform(-h, h, n)
        z = rng.uniform(-0.06, 0.0, n)
        sign = 1.0 if f[0] == "+" else -1.0
        xyz = [np.full(n, sign * h), a, z] if f[1] == "x" else [a, np.full(n, sign * h), z]
        out.append(np.stack(xyz, axis=1))
    return np.concatenate(out)


def _error(rng) -> np.ndarray:
    """A camera error like the realistic profile's: 1.5 mm and 0.5 deg, random directions."""
    turn = rng.standard_normal(3)
    move = rng.standard_normal(3)
    R = Rotation.from_rotvec(np.radians(0.5) * turn / np.linalg.norm(turn)).as_matrix()
    return G.make(R, 0.0015 * move / np.linalg.norm(move))


@pytest.mark.parametrize("seed", range(5))
def test_the_peg_seen_gives_the_camera_error_back(seed):
    """Two faces in view: the correction puts the opening 30 mm ahead of the tip back on
    the tool's axis to within 0.1 mm (0.2 mm noise on every point), from any tool pose;
    along the axis (no end face in view) it is left as it was."""
    rng = np.random.default_rng(seed)
    tcp = G.make(Rotation.random(random_state=seed).as_matrix(), rng.uniform(-0.5, 0.5, 3))
    peg = _square_peg_faces(rng, 600) + rng.normal(0, 0.0002, (1200, 3))
    E = tcp @ _error(rng) @ G.inv(tcp)  # true world -> the camera's world
    seen = _move(E, _move(tcp, peg))
    C = tcp @ peg_correction(seen, tcp, "square") @ G.inv(tcp)
    opening = _move(tcp, np.array([[0.0, 0.0, 0.03]]))
    axis = tcp[:3, 2]

    def lateral(T):
        d = (_move(T, opening) - opening)[0]
        return np.linalg.norm(d - (d @ axis) * axis)

    before, after = lateral(E), lateral(C @ E)
    assert after < 0.0001 and after < before / 4, (before, after)


def test_what_the_peg_does_not_show_stays_put():
    """One face in view: its normal's move and the tilt are recovered; points moved along
    the axis (up the face, no end in view) ask for no move along it: none is invented."""
    rng = np.random.default_rng(0)
    peg = _square_peg_faces(rng, 1500, faces=("+x",))
    E = G.make(Rotation.from_rotvec([0.0, np.radians(0.4), 0.0]).as_matrix(), [0.001, 0.0, 0.0])
    C = peg_correction(_move(E, peg), np.eye(4), "square")
    assert np.allclose((C @ E)[:3, :3], np.eye(3), atol=1e-5)
    assert np.allclose((C @ E)[:3, 3], 0.0, atol=1e-4)  # across the face: from its edges
    shifted = _move(G.make(np.eye(3), [0.0, 0.0, -0.002]), peg)
    assert abs(peg_correction(shifted, np.eye(4), "square")[2, 3]) < 1e-6


@pytest.mark.parametrize("seed", range(3))
def test_a_face_seen_whole_places_the_peg_across_it(seed):
    """One face in view with both its edges, 1 mm of noise, the camera 1.5 mm off along the
    face: the opening 30 mm ahead of the tip comes back within 0.2 mm (the plane fit alone
    leaves the 1.5 mm). Half the face in view: no edge pair, no move across it."""
    rng = np.random.default_rng(seed)
    E = G.make(np.eye(3), [0.0, 0.0015, 0.0])
    face = _square_peg_faces(rng, 2000, faces=("+x",))
    seen = _move(E, face) + rng.normal(0, 0.001, face.shape)
    C = peg_correction(seen, np.eye(4), "square")
    opening = np.array([[0.0, 0.0, 0.03]])
    assert np.linalg.norm((_move(C @ E, opening) - opening)[0, :2]) < 0.0002
    half = _move(E, face[face[:, 1] > 0])
    assert abs(peg_correction(half, np.eye(4), "square")[1, 3]) < 1e-6


def test_a_face_seen_edge_on_does_not_pull_the_fit():
    """The face towards the camera in full and a few points of each side face at its edges
    (seen edge-on), 1 mm of noise, no camera error: the opening 50 mm ahead of the tip stays
    within 0.3 mm. Those few points' face assignment is biased by the noise; fitted, they
    pulled the peg ~1 mm sideways."""
    rng = np.random.default_rng(0)
    h = peg_half_extent("square")
    front = _square_peg_faces(rng, 1500, faces=("+x",))
    edges = []
    for sign in (1.0, -1.0):
        z = rng.uniform(-0.03, 0.0, 20)
        edges.append(np.stack([rng.uniform(h - 0.004, h, 20), np.full(20, sign * h), z], 1))
    cloud = np.concatenate([front, *edges]) + rng.normal(0, 0.001, (1540, 3))
    C = peg_correction(cloud, np.eye(4), "square")
    moved = _move(C, np.array([[0.0, 0.0, 0.05]]))[0] if C is not None else np.zeros(3)
    assert np.hypot(moved[0], moved[1]) < 0.0003, moved


def test_no_peg_in_view_gives_no_correction():
    rng = np.random.default_rng(0)
    few = _square_peg_faces(rng, MIN_PEG_POINTS // 4)
    assert peg_correction(few, np.eye(4), "square") is None
    beside = rng.uniform(0.05, 0.1, (5000, 3))  # a part's surface away from the peg
    assert peg_correction(beside, np.eye(4), "square") is None


def test_the_env_puts_the_camera_on_the_profiles_mount_and_renders_it_unbiased(make_env, tmp_path):
    """A peg-view mount sees the peg; its face comes out where it is (the renderer's
    whole-millimetre truncation undone: it put the face 0.75 mm nearer the camera)."""
    env = make_env(
        "PegInsert6DoF-v1", obs_mode="pointcloud", sensor=_profile(tmp_path, "pv", mount="peg_view")
    )
    u = env.unwrapped
    obs, _ = env.reset(seed=0)
    assert TaskSpec.of_env(env).mount == MOUNTS["peg_view"]
    gl = u.scene.sensors["wrist_camera"].get_params()["cam2world_gl"][0].numpy()
    in_tool = G.inv(u.flange_matrix()) @ gl.astype(np.float64) @ G.inv(SAPIEN_CAM_TO_GL)
    assert np.allclose(in_tool, MOUNTS["peg_view"].in_tool(), atol=1e-5)
    tcp = u.agent.tcp.pose.to_transformation_matrix()[0].numpy().astype(np.float64)
    p = world_to_tool(valid_world_points(obs["pointcloud"]["xyzw"][0].numpy()), tcp)
    h = peg_half_extent("square")
    face = (np.abs(p[:, 1]) < h - 0.004) & (p[:, 2] > -0.05) & (np.abs(p[:, 0] - h) < 0.004)
    assert face.sum() > 1000
    assert abs(np.median(p[face, 0]) - h) < 0.0002


def test_an_agent_trained_on_one_mount_runs_on_it_whatever_the_profile_says(make_env, tmp_path):
    """`camera_mount` (an agent's env option) moves the camera to a named mount, in the
    render and in what the agents are told; KOVIS collects and runs on the same one."""
    from cfvs_maniskill.policies.kovis.agent import KOVISAgent
    from cfvs_maniskill.policies.kovis.collect import KINDS

    profile = _profile(tmp_path, "pv", mount="peg_view")
    env = make_env(
        "PegInsert3DoF-v1", obs_mode="pointcloud", sensor=profile, camera_mount="tip_view"
    )
    u = env.unwrapped
    env.reset(seed=0)
    assert TaskSpec.of_env(env).mount == MOUNTS["tip_view"]
    gl = u.scene.sensors["wrist_camera"].get_params()["cam2world_gl"][0].numpy()
    in_tool = G.inv(u.flange_matrix()) @ gl.astype(np.float64) @ G.inv(SAPIEN_CAM_TO_GL)
    assert np.allclose(in_tool, MOUNTS["tip_view"].in_tool(), atol=1e-5)
    mount = KOVISAgent.env_options["camera_mount"]
    assert mount in MOUNTS and KINDS["kovis"].env_kwargs["camera_mount"] == mount
    with pytest.raises(SensorProfileError, match="mount.name"):
        make_env("PegInsert3DoF-v1", sensor=profile, camera_mount="no_such_mount")


def test_training_samples_see_the_cloud_moved_onto_the_peg_as_the_agent_does():
    """The collector reads a view as the agent does (`seen_object_points`): the camera's
    error, measured on the peg's points, is taken out of the object points it keeps."""
    from types import SimpleNamespace

    import torch

    from cfvs_maniskill.policies.cfvs.collect import seen_object_points

    rng = np.random.default_rng(3)
    tcp = G.make(np.diag([1.0, -1.0, -1.0]), [0.4, 0.1, 0.3])  # tool pointing down
    peg = _square_peg_faces(rng, 800)
    part = rng.uniform([-0.03, -0.03, 0.025], [0.03, 0.03, 0.035], (3000, 3))  # ahead of the tip
    E = tcp @ G.make(np.eye(3), [0.0015, -0.001, 0.0]) @ G.inv(tcp)  # the camera's error
    world = _move(E, _move(tcp, np.concatenate([peg, part])))
    xyzw = np.concatenate([world, np.ones((len(world), 1))], axis=1)[None].astype(np.float32)
    obs = {"pointcloud": {"xyzw": torch.from_numpy(xyzw)}}
    kept = seen_object_points(SimpleNamespace(peg="square", peg_chamfer=0.0), obs, tcp)
    assert len(kept) == len(part)
    assert np.abs(np.sort(kept, axis=0) - np.sort(part, axis=0)).max() < 2e-4
