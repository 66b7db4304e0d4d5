"""No privileged data reaches an agent: agents are built from the task's nominal
constants, seeded from the episode seed, and see only what a robot's sensors report."""

from __future__ import annotations

import dataclasses
import re

import gymnasium as gym
import numpy as np
import pytest
import sapien
import torch

from cfvs_maniskill.control.executor import Executor
from cfvs_maniskill.envs.task_config import TaskConfig
from cfvs_maniskill.episode import agent_seed, run_episode
from cfvs_maniskill.policies.base import Agent, Observation
from cfvs_maniskill.policies.interface import ALLOWED_OBS, TaskSpec
from cfvs_maniskill.policies.registry import AGENTS, PRIVILEGED, agent_env_kwargs, make_agent
from cfvs_maniskill.robots.ur5 import STEREO_UIDS

ENV_ID = "PegInsert6DoF-v1"
FORBIDDEN_TYPES = (gym.Env, gym.Wrapper, TaskConfig, sapien.Scene, sapien.Entity)
"""Anything an agent could read the truth from: the env (any wrapper), the task's full
config (it lists the objects), the simulator's scene or its entities."""


def _reachable(root, limit: int = 20000):
    """Every object reachable from `root` through attributes, containers and dataclass
    fields (what an agent's code could get at without importing anything)."""
    seen, stack = set(), [root]
    while stack and len(seen) < limit:
        x = stack.pop()
        if id(x) in seen or isinstance(x, str | bytes | int | float | bool | type(None)):
            continue
        seen.add(id(x))
        yield x
        if isinstance(x, np.ndarray | torch.Tensor):
            continue
        if isinstance(x, dict):
            stack.extend(x.keys())
            stack.extend(x.values())
        elif isinstance(x, list | tuple | set | frozenset):
            stack.extend(x)
        if hasattr(x, "__dict__"):
            stack.extend(vars(x).values())
        for slot in getattr(type(x), "__slots__", ()):
            stack.append(getattr(x, slot, None))
        if callable(x) and getattr(x, "__closure__", None):
            stack.extend(c.cell_contents for c in x.__closure__)


@pytest.mark.parametrize("name", [a for a in AGENTS if a not in PRIVILEGED])
def test_agents_cannot_reach_the_env(make_env, name):
    env_id = "PegInsert3DoF-v1" if name == "kovis" else ENV_ID  # KOVIS: stereo on 3-DoF
    env = make_env(env_id, **agent_env_kwargs(name))
    agent = make_agent(name, env)
    assert not agent.privileged
    leaks = [type(x).__name__ for x in _reachable(agent) if isinstance(x, FORBIDDEN_TYPES)]
    assert not leaks, f"{name} can reach {sorted(set(leaks))}"
    specs = [x for x in _reachable(agent) if isinstance(x, TaskSpec)]
    assert specs and all(s.env_id == env_id for s in specs)


def test_each_agent_gets_the_observations_its_class_asks_for():
    assert agent_env_kwargs("oracle") == {"obs_mode": "state"}
    # KOVIS's image networks learnt the flange_side bracket's views; it asks for that mount.
    assert agent_env_kwargs("kovis") == {
        "obs_mode": "rgbd",
        "stereo": True,
        "camera_mount": "flange_side",
    }
    assert agent_env_kwargs("cfvs_no_map") == {"obs_mode": "pointcloud"}
    assert agent_env_kwargs("tests.crashing_agent:CrashingAgent") == {"obs_mode": "state"}
    with pytest.raises(KeyError, match="unknown agent 'nosuch'"):
        agent_env_kwargs("nosuch")


def test_only_the_oracle_is_privileged(make_env):
    env = make_env(ENV_ID, obs_mode="state")
    assert {"oracle"} == PRIVILEGED and make_agent("oracle", env).privileged
    # TaskSpec has the task's nominal constants and nothing per episode.
    names = {f.name for f in dataclasses.fields(TaskSpec)}
    assert not names & {"objects", "hole_pose", "object", "tilt_deg", "yaw_deg", "source"}


class Spy(Agent):
    """Records everything handed to the agent it wraps."""

    def __init__(self, inner: Agent):
        self.inner, self.name, self.obs_mode = inner, inner.name, inner.obs_mode
        self.env_options = inner.env_options
        self.max_decisions = inner.max_decisions
        self.resets: list = []
        self.seen: list[Observation] = []

    def reset(self, seed):
        self.resets.append(seed)
        self.inner.reset(seed)

    def act(self, observation):
        self.seen.append(observation)
        return self.inner.act(observation)


def _keys(d: dict, prefix: str = "") -> set[str]:
    out = set()
    for k, v in d.items():
        out |= _keys(v, f"{prefix}{k}/") if isinstance(v, dict) else {prefix + k}
    return out


@pytest.mark.parametrize(("name", "env_id"), [("cfvs", ENV_ID), ("kovis", "PegInsert3DoF-v1")])
def test_agents_are_handed_only_what_a_robot_has(make_env, name, env_id):
    """Through a whole episode: reset gets a seed derived from the episode's (an int, never
    the env's seed, which fixes the scene) and nothing else; each
    observation holds only the wrist camera's cloud or images (no segmentation, no true
    poses, no sensor extrinsics, no noise-free depth of the stereo imagers), the tcp pose,
    joint angles and the wrist wrench."""
    env = make_env(env_id, **agent_env_kwargs(name), sensor="realistic")
    spy = Spy(make_agent(name, env))
    run_episode(env, spy, Executor(env), seed=21)
    assert spy.resets == [agent_seed(21)] and type(spy.resets[0]) is int
    assert agent_seed(21) != 21 and agent_seed(22) != agent_seed(21)
    assert spy.seen
    allowed = (
        {f"pointcloud/{k}" for k in ALLOWED_OBS["pointcloud"]}
        | {f"sensor_data/wrist_camera/{k}" for k in ALLOWED_OBS["sensor_data"]}
        | {f"sensor_data/{cam}/rgb" for cam in STEREO_UIDS}
    )
    for o in spy.seen:
        assert {f.name for f in dataclasses.fields(o)} == {"obs", "tcp_pose", "qpos", "wrench"}
        keys = _keys(o.obs)
        assert keys and keys <= allowed, keys - allowed
        assert o.tcp_pose.shape == (4, 4) and o.qpos.shape == (6,) and o.wrench.shape == (6,)


def test_an_agents_randomness_follows_the_episode_seed(make_env):
    """Same seed, same episode; CFVS draws its point subsets from the episode seed (not from
    the scene it should not know)."""
    env = make_env(ENV_ID, obs_mode="pointcloud")
    agent, ex = make_agent("cfvs", env), Executor(env)
    a = run_episode(env, agent, ex, seed=33)
    b = run_episode(env, agent, ex, seed=33)
    assert (a.success, a.steps, a.lateral_offset_m) == (b.success, b.steps, b.lateral_offset_m)
    agent.reset(33)
    first = agent.rng.random()
    agent.reset(33)
    assert agent.rng.random() == first


def test_records_carry_the_true_residual_after_each_move(make_env, tmp_path):
    """The runner (not the agent) measures the true error after each move: the oracle's one
    move lands on the pre-insertion pose; the report tabulates it per move and sensor."""
    from cfvs_maniskill.report import residuals

    env = make_env(ENV_ID, obs_mode="state")
    r = run_episode(env, make_agent("oracle", env), Executor(env), seed=4)
    assert len(r.move_residuals) == 1
    lateral_mm, tilt_deg = r.move_residuals[0]
    assert lateral_mm < 1.0 and tilt_deg < 0.5
    rec = {**r.to_json(), "label": "oracle"}
    text = residuals.table([rec, {**rec, "sensor": "realistic", "move_residuals": [[3.0, 2.0]]}])
    assert "| PegInsert6DoF | oracle | realistic | 1 | 1 | 3.00 / 3.00 | 2.00 / 2.00 |" in text
    # After the last move, whichever it was: where the insertion starts from.
    two = {**rec, "sensor": "d435", "move_residuals": [[9.0, 1.0], [0.5, 0.25]]}
    rows = [x for x in residuals.table([two]).splitlines() if "| d435 |" in x]
    assert rows[-1] == "| PegInsert6DoF | oracle | d435 | last | 1 | 0.50 / 0.50 | 0.25 / 0.25 |"
    assert [x.split(" | ")[3] for x in rows] == ["1", "2", "last"]
    # The realistic profile's hand-eye floor is quoted beside it (sensing/floor.py), trusting
    # the calibration and calibrated on the table; the ideal profile (no errors) has none.
    assert "hand-eye floor" in text and "`ideal`" not in text
    # 1.5 mm / 0.5 deg of hand-eye error: the floor is above the translation alone, and the
    # table calibration takes part of it away.
    m = re.search(r"`realistic` ([\d.]+) mm / ([\d.]+) deg \(([\d.]+) / ([\d.]+)\)", text)
    assert m, text
    lateral, tilt, calibrated_lateral, calibrated_tilt = map(float, m.groups())
    assert 1.5 < lateral < 5.0 and 0.4 < tilt < 1.0
    assert calibrated_lateral < lateral and calibrated_tilt < tilt
    assert residuals.plot([rec], tmp_path, agent="oracle").read_bytes()[:4] == b"\x89PNG"


def test_cfvs_with_a_weights_folder_loads_those_files(make_env, tmp_path):
    """`cfvs@DIR`: CFVS with the networks in DIR (here the shipped 6-DoF pair copied under
    another layout), the same forward as the shipped agent; a missing folder is named."""
    import shutil

    from cfvs_maniskill.policies.cfvs.agent import weights_for
    from cfvs_maniskill.policies.cfvs.config import WEIGHTS_DIR

    env = make_env(ENV_ID, obs_mode="pointcloud")
    shipped = weights_for("PegInsert6DoF", "square", WEIGHTS_DIR)
    (tmp_path / "square").mkdir()
    for net, p in shipped.items():
        shutil.copy(p, tmp_path / "square" / f"{net if net == 'oakn' else 'opnv'}.pt")
    mine = make_agent(f"cfvs@{tmp_path}", env)
    ours = make_agent("cfvs", env)
    assert mine.name == f"cfvs@{tmp_path}"
    assert mine.opn_meta["data_sha256"] == ours.opn_meta["data_sha256"]
    with pytest.raises(KeyError, match="no weights folder"):
        make_agent(f"cfvs@{tmp_path / 'nope'}", env)
