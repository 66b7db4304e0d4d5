"""The user's own files without editing the package: a task file by path, the user folder
($CFVS_HOME) for tasks, sensor profiles, hole objects and weights, and the report on
records of the user's own hole shapes."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import gymnasium as gym
import pytest

from cfvs_maniskill import resources
from cfvs_maniskill.envs.lookup import find_task, make_args
from cfvs_maniskill.envs.task_config import TaskConfigError

from .conftest import ROOT, run_cli

BLOCK = "split: test\nbody:\n  box: {size: [0.15, 0.13, 0.07]}\ncolor: [0.4, 0.5, 0.6]\n"


def _my_task(tmp_path, name="my_3dof", **edits) -> str:
    text = (resources.bundled("tasks") / "PegInsert3DoF.yaml").read_text()
    text += "".join(f"{k}: {v}\n" for k, v in edits.items())  # later keys win in YAML
    path = tmp_path / f"{name}.yaml"
    path.write_text(text)
    return str(path)


def test_bundled_files_are_read_through_the_package():
    # In a checkout the bundle links to the top-level folders; the names in records are
    # the repository's either way.
    assert (resources.bundled("tasks") / "PegInsert6DoF.yaml").resolve() == (
        ROOT / "tasks" / "PegInsert6DoF.yaml"
    )
    assert resources.key(ROOT / "sensors" / "realistic.yaml") == "sensors/realistic.yaml"
    assert resources.key(resources.bundled("agents") / "cfvs" / "tasks.yaml") == (
        "agents/cfvs/tasks.yaml"
    )


def test_gym_make_takes_a_task_file(tmp_path):
    path = _my_task(tmp_path, max_episode_steps=9, workspace_x="[0.45, 0.5]")
    env = gym.make("PegInsert-v1", task_file=path, obs_mode="state", max_episode_steps=9)
    try:
        assert env.unwrapped.task.name == "my_3dof"
        assert env.unwrapped.task.workspace_x == (0.45, 0.5)
        env.reset(seed=0)
        truncated = [env.step(env.action_space.sample() * 0)[3] for _ in range(9)]
        assert bool(truncated[-1]) and not any(bool(t) for t in truncated[:-1])
    finally:
        env.close()
    with pytest.raises(ValueError, match="task_file=PATH"):
        gym.make("PegInsert-v1", obs_mode="state")


def test_run_takes_a_copied_edited_task_file(tmp_path):
    path = _my_task(tmp_path, workspace_y="[-0.05, 0.05]")
    env_id, kwargs = make_args(find_task(path))
    assert env_id == "PegInsert-v1" and kwargs["task_file"] == path
    out = tmp_path / "records.jsonl"
    r = run_cli("cfvs_maniskill.run", "--task", path, "--agent", "oracle", "--episodes", "1",
                "--out", str(out))  # fmt: skip
    assert r.returncode == 0, r.stderr[-2000:]
    rec = json.loads(out.read_text())
    assert rec["task"] == "my_3dof" and rec["success"]
    assert rec["provenance"]["task"]["file"] == path


@pytest.mark.slow
def test_a_task_file_with_its_own_clearance_runs_as_written(tmp_path):
    """A copied 6-DoF task with a 2 mm fit and nothing else changed: it gets the contact
    offset below its play (TaskConfig.contact_offset) and CFVS inserts."""
    text = (resources.bundled("tasks") / "PegInsert6DoF.yaml").read_text()
    path = tmp_path / "my_2mm.yaml"
    path.write_text(text.replace("clearance: 0.004", "clearance: 0.002"))
    out = tmp_path / "records.jsonl"
    r = run_cli("cfvs_maniskill.run", "--task", str(path), "--episodes", "2", "--seed", "7",
                "--out", str(out))  # fmt: skip
    assert r.returncode == 0, r.stderr[-2000:]
    recs = [json.loads(line) for line in out.read_text().splitlines()]
    assert [(x["task"], x["success"]) for x in recs] == [("my_2mm", True)] * 2


def test_a_task_file_named_like_a_bundled_one_must_be_that_task(tmp_path):
    same = tmp_path / "PegInsert3DoF.yaml"
    shutil.copy(resources.bundled("tasks") / "PegInsert3DoF.yaml", same)
    assert find_task(str(same)).env_id == "PegInsert3DoF-v1"  # the same file: the same task
    (tmp_path / "mine").mkdir()
    edited = _my_task(tmp_path / "mine", name="PegInsert3DoF", init_aim_deg=4.0)
    with pytest.raises(TaskConfigError, match="name of its own") as e:
        find_task(edited)
    assert e.value.file == edited
    r = run_cli("cfvs_maniskill.run", "--task", edited, "--episodes", "1")
    assert r.returncode == 2 and "name of its own" in r.stderr and "Traceback" not in r.stderr
    r = run_cli("cfvs_maniskill.run", "--task", str(tmp_path / "nowhere.yaml"))
    assert r.returncode == 2 and "no such task file" in r.stderr


def test_user_folder_adds_tasks_sensors_holes_and_weights(tmp_path):
    home = tmp_path / "home"
    (home / "tasks").mkdir(parents=True)
    _my_task(home / "tasks", name="MyBlock3DoF", objects="[my_block]")
    (home / "sensors").mkdir()
    shutil.copy(resources.bundled("sensors") / "iid_3mm.yaml", home / "sensors" / "my_cam.yaml")
    (home / "assets" / "holes").mkdir(parents=True)
    (home / "assets" / "holes" / "my_block.yaml").write_text(BLOCK)
    shutil.copytree(resources.bundled("agents") / "cfvs" / "round",
                    home / "agents" / "cfvs" / "mine" / "round")  # fmt: skip
    probe = """
import json, cfvs_maniskill, gymnasium as gym
from cfvs_maniskill.policies.registry import resolve_agent
from cfvs_maniskill.objects.library import load_library
from cfvs_maniskill.sensing.profile import available_profiles
resolve_agent("cfvs@mine")
env = gym.make("MyBlock3DoF-v1", obs_mode="state", sensor="my_cam")
print(json.dumps([sorted(cfvs_maniskill.TASKS), available_profiles(),
                  env.unwrapped.object_names, "my_block" in load_library().specs]))
"""
    env = {**os.environ, resources.HOME_ENV: str(home)}
    r = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True,
                       cwd=tmp_path, timeout=300)  # fmt: skip
    assert r.returncode == 0, r.stderr[-2000:]
    tasks, sensors, objects, found = json.loads(r.stdout.strip().splitlines()[-1])
    assert "MyBlock3DoF" in tasks and "PegInsert6DoF" in tasks
    assert "my_cam" in sensors and "ideal" in sensors
    assert objects == ["my_block"] and found


def test_report_covers_records_on_the_users_own_shapes(tmp_path):
    holes = tmp_path / "holes"
    holes.mkdir()
    (holes / "my_block.yaml").write_text(BLOCK)
    task = _my_task(tmp_path, objects="[my_block]")
    ev = tmp_path / "ev"
    r = run_cli("cfvs_maniskill.eval", "--out", str(ev), "--tasks", task, "--agents", "oracle",
                "--objects", "my_block", "--assets", str(holes), "--episodes-per-object", "1",
                "--init-errors", "small", "--workers", "0")  # fmt: skip
    assert r.returncode == 0, r.stderr[-2000:]
    r = run_cli("cfvs_maniskill.report", str(ev), "--out", str(tmp_path / "rep"), "--no-videos")
    assert r.returncode == 2 and "--assets" in r.stderr  # nothing on known objects
    r = run_cli("cfvs_maniskill.report", str(ev), "--out", str(tmp_path / "rep"), "--no-videos",
                "--assets", str(holes))  # fmt: skip
    assert r.returncode == 0, r.stderr[-2000:]
    text = (tmp_path / "rep" / "README.md").read_text()
    row = next(x for x in text.splitlines() if x.startswith("| oracle | 1.00"))
    assert "my_block" in text and row.endswith("| 1.00 / - |")
    assert "| oracle | my_3dof | ideal | 1 |" in text  # the provenance table
