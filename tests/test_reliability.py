"""Reliability: faults inside an episode, kills, and full disks lose nothing and
say what went wrong. (Bad inputs: test_validation.py, test_cfvs.py, test_run_cli.py,
test_eval.py; Ray worker deaths and torn lines: test_eval.py; killed collections:
test_data.py.)"""

from __future__ import annotations

import json
import os
import random
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from cfvs_maniskill.control.executor import Executor
from cfvs_maniskill.control.robot import SimRobot
from cfvs_maniskill.episode import run_episode
from cfvs_maniskill.policies.base import Action, Agent
from cfvs_maniskill.policies.oracle.agent import OracleAgent

from .conftest import ROOT, run_cli

ENV = "PegInsert3DoF-v1"


class _Scripted(Agent):
    """Does `first(env)` on its first decision, then asks to insert."""

    name = "scripted"

    def __init__(self, env, first):
        self.env, self.first = env, first

    def reset(self, info):
        self.turn = 0

    def act(self, observation):
        self.turn += 1
        return self.first(self.env) if self.turn == 1 else Action.insert()


def _then_oracle_succeeds(env, seed: int = 11) -> None:
    """The same env, right after the fault: a normal episode still succeeds."""
    r = run_episode(env, OracleAgent(env), Executor(env), seed=seed)
    assert r.success, r.reason


def _nan_pose(env):
    return Action.move(np.full((4, 4), np.nan))


def _far_pose(env):
    T = env.unwrapped.tcp_matrix().copy()
    T[:3, 3] += [3.0, 0.0, 0.0]  # 3 m away: beyond the UR5's reach
    return Action.move(T)


def _blow_up(env):
    # What an exploding solver leaves behind: non-finite joint velocities.
    robot = env.unwrapped.agent.robot
    robot.set_qvel(robot.get_qvel() * np.nan)
    return Action.move(env.unwrapped.tcp_matrix())


def _raises(env):
    return 1 / 0


AGENT_FAULTS = {
    _nan_pose: "non-finite pose",
    _raises: "ZeroDivisionError: division by zero",
    (lambda env: None): "returned None, not an Action",
    (lambda env: "insert"): "returned 'insert', not an Action",
    (lambda env: Action("jump")): "action kind 'jump'; expected one of move, insert, give_up",
    (lambda env: Action("move", pose=np.eye(3))): "a pose of shape (3, 3)",
    (lambda env: Action("move")): "move with no pose",
}


@pytest.mark.parametrize(
    "fault, words",
    [
        *AGENT_FAULTS.items(),
        (_far_pose, "unreachable"),
        (_blow_up, "simulation blew up"),
    ],
)
def test_a_faulty_episode_fails_with_a_reason_and_the_next_one_runs(make_env, fault, words):
    """An agent that raises or returns what is not an action fails its episode, the error
    recorded (type, message, decision); so do moves the robot cannot make."""
    env = make_env(ENV, obs_mode="state")
    r = run_episode(env, _Scripted(env, fault), Executor(env), seed=10)
    assert not r.success and words in r.reason, r.reason
    if fault in AGENT_FAULTS:
        assert r.agent_error["agent"] == "scripted" and r.agent_error["decision"] == 1
        assert "agent scripted failed at decision 1" in r.reason
    else:
        assert r.agent_error is None
    # A whole record, as the run and eval commands write it.
    rec = json.loads(json.dumps(r.to_json()))
    assert rec["object"] == env.unwrapped.episode_info["object"] and rec["seed"] == 10
    _then_oracle_succeeds(env)


def test_a_step_that_makes_the_state_non_finite_is_named_by_that_step(make_env, monkeypatch):
    """A blow-up is caught after the step that makes it, not only before the next one: on
    an episode's last step there is no next one."""
    env = make_env(ENV, obs_mode="state")
    env.reset(seed=10)
    robot = SimRobot(env)
    step = env.step

    def exploding_step(action):
        out = step(action)
        r = env.unwrapped.agent.robot
        r.set_qvel(r.get_qvel() * np.nan)
        return out

    monkeypatch.setattr(env, "step", exploding_step)
    with pytest.raises(FloatingPointError, match="NaN"):
        robot.command(robot.joints())
    monkeypatch.undo()
    _then_oracle_succeeds(env)


EVAL_ARGS = [
    "--tasks", "PegInsert3DoF", "--agents", "oracle", "--objects", "cuboid_test_1",
    "cylinder", "--init-errors", "small", "--episodes-per-object", "20", "--workers", "1",
]  # fmt: skip
EVAL_JOBS = 40


def _records(path: Path) -> dict[str, dict]:
    lines = [json.loads(x) for x in path.read_text().splitlines() if x.strip()]
    keys = [r["key"] for r in lines]
    assert len(keys) == len(set(keys)), "a job was recorded twice"
    return {r["key"]: r for r in lines}


def _outcomes(recs: dict[str, dict]) -> dict[str, tuple]:
    return {k: (r["seed"], r["object"], r["success"]) for k, r in recs.items()}


@pytest.fixture(scope="module")
def eval_reference(tmp_path_factory) -> dict[str, dict]:
    out = tmp_path_factory.mktemp("ref")
    r = run_cli("cfvs_maniskill.eval", *EVAL_ARGS, "--out", str(out))
    assert r.returncode == 0, r.stderr[-2000:]
    recs = _records(out / "episodes.jsonl")
    assert len(recs) == EVAL_JOBS
    return recs


KILLS = 6
"""Three SIGKILLs and three SIGINTs, alternating, each at a random point."""


@pytest.mark.slow
def test_eval_killed_six_times_at_random_points_has_every_job_once(eval_reference, tmp_path):
    rng = random.Random(0)
    cmd = [sys.executable, "-m", "cfvs_maniskill.eval", *EVAL_ARGS, "--out", str(tmp_path)]
    results = tmp_path / "episodes.jsonl"
    kills = 0

    def lines() -> int:
        return len(results.read_bytes().splitlines()) if results.exists() else 0

    log = tmp_path / "run.log"
    while kills < KILLS:
        with open(log, "w") as out:
            proc = subprocess.Popen(
                cmd, cwd=ROOT, stdout=out, stderr=subprocess.STDOUT, start_new_session=True,
                preexec_fn=_sigint_default,
            )  # fmt: skip
        # A random point: after 0-3 more finished episodes (0: during start-up), plus a
        # random fraction of the next one, whatever this machine's speed.
        target, deadline = lines() + rng.randint(0, 3), time.time() + 120
        while lines() < target and proc.poll() is None and time.time() < deadline:
            time.sleep(0.02)
        time.sleep(rng.uniform(0.0, 0.4))
        if proc.poll() is not None:
            break  # finished before this kill: nothing left to interrupt
        sig = signal.SIGINT if kills % 2 else signal.SIGKILL
        os.killpg(proc.pid, sig)  # the whole group: the main process and its worker
        proc.wait(timeout=120)
        kills += 1
        if results.exists():
            _records(results)  # readable and no job twice after every kill
    if kills < KILLS:  # a run outpaced its kill and ended by itself: it must have finished
        assert proc.returncode == 0, f"exit {proc.returncode}:\n{log.read_text()[-3000:]}"
        assert kills >= 5, f"only {kills} kills before the evaluation finished"
    r = run_cli("cfvs_maniskill.eval", *EVAL_ARGS, "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr[-2000:]
    got = _records(results)
    assert _outcomes(got) == _outcomes(eval_reference)


def _sigint_default() -> None:
    """A shell that runs the tests in the background (`cmd &`) makes its children ignore
    SIGINT, and Python keeps an inherited SIG_IGN: give the evaluation Ctrl-C back."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _limit_file_size(limit: int):
    """A child whose writes past `limit` bytes fail (EFBIG), as on a full disk."""

    def apply():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # fail the write, don't kill
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return apply


def test_disk_full_while_writing_results_keeps_the_file_readable(eval_reference, tmp_path):
    """The limit holds for the workers too (a full disk does): one that cannot write what
    its renderer maps dies and its job is recorded as crashed; the second run, with room
    again and --retry-crashed, leaves exactly the reference's outcomes."""
    cmd = [sys.executable, "-m", "cfvs_maniskill.eval", *EVAL_ARGS, "--out", str(tmp_path)]
    one = len(json.dumps(next(iter(eval_reference.values())))) + 1
    r = subprocess.run(
        cmd, cwd=ROOT, capture_output=True, text=True, preexec_fn=_limit_file_size(3 * one + 50)
    )
    results = tmp_path / "episodes.jsonl"
    assert r.returncode == 1
    assert f"{results}: cannot append a result" in r.stderr and "intact" in r.stderr
    assert "Traceback" not in r.stderr
    kept = _records(results)  # every line whole
    assert 1 <= len(kept) < EVAL_JOBS
    r = run_cli("cfvs_maniskill.eval", *EVAL_ARGS, "--out", str(tmp_path), "--retry-crashed")
    assert r.returncode == 0, r.stderr[-2000:]
    from cfvs_maniskill.eval.results import read_done  # a retried job's last record counts

    assert _outcomes(read_done(results)) == _outcomes(eval_reference)


@pytest.mark.slow
def test_disk_full_while_collecting_keeps_the_samples(tmp_path):
    out = tmp_path / "coarse.h5"
    args = ["--task", "PegInsert3DoF", "--kind", "coarse", "--samples", "80", "--points", "256"]
    cmd = [sys.executable, "-m", "cfvs_maniskill.data", "collect", *args, "--out", str(out)]
    # Room for each 40-sample chunk (~0.55 MB) but not for the merged 80-sample file.
    r = subprocess.run(
        cmd, cwd=ROOT, capture_output=True, text=True, preexec_fn=_limit_file_size(800_000)
    )
    assert r.returncode == 2, r.stderr[-2000:]
    assert "cannot write (File too large)" in r.stderr and "all 80 samples are kept" in r.stderr
    assert "Traceback" not in r.stderr
    assert not out.exists() and not out.with_name(out.name + ".tmp").exists()
    assert len(list(Path(f"{out}.parts").glob("part-*.npz"))) == 2
    r = run_cli("cfvs_maniskill.data", "collect", *args, "--out", str(out))
    assert r.returncode == 0, r.stderr[-2000:]
    with h5py.File(out) as f:
        assert np.array_equal(f["sample_index"][:], np.arange(80))
        pts = f["points"][:]
        assert len(np.unique(pts.reshape(80, -1), axis=0)) == 80
