"""The package as a pip-install user gets it: the wheel is built, installed into a fresh
virtual environment outside the repository beside the locked dependencies, and used from
another folder (gym.make on every task, a CFVS episode with the shipped weights, a task
file and a hole folder of the user's, the report on their records)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

from .conftest import ROOT, run_cli

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("wheel")]  # one wheel, one worker

BLOCK = "split: test\nbody:\n  box: {size: [0.15, 0.13, 0.07]}\ncolor: [0.4, 0.5, 0.6]\n"


SOURCES = ("pyproject.toml", "README.md", "cfvs_maniskill_setup.py", "cfvs_maniskill", "tasks",
           "sensors", "assets", "agents")  # fmt: skip
"""What the wheel is built from: the package and the folders its bundled/ links point to."""


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    # Built from a copy: a build in the checkout writes its build/ and egg-info folders,
    # which other tests running at the same time may be reading or writing too.
    src = tmp_path_factory.mktemp("src")
    skip = shutil.ignore_patterns("__pycache__", "*.egg-info")
    for name in SOURCES:
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, src / name, symlinks=True, ignore=skip)
        else:
            shutil.copy2(ROOT / name, src / name)
    dist = tmp_path_factory.mktemp("dist")
    r = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
         "-w", str(dist), str(src)],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    return next(dist.glob("cfvs_maniskill-*.whl"))


@pytest.fixture(scope="module")
def user(tmp_path_factory, wheel):
    """A fresh venv with the wheel, a home and a cache of its own, and a work folder. Its
    dependencies are the locked ones this checkout's set-up installed (seen through a .pth
    file: installing them again from the index takes minutes and tests pip, not us); `pip
    check` proves the wheel's declared requirements are met by them."""
    root = tmp_path_factory.mktemp("user")
    venv = root / "venv"
    # No pip of its own: the locked one (its setuptools too) comes through the .pth file.
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True,
                   timeout=300)  # fmt: skip
    site = next((venv / "lib").glob("python3*/site-packages"))
    locked = next(p for p in map(Path, sys.path) if p.name == "site-packages" and p.is_dir())
    (site / "locked_dependencies.pth").write_text(f"{locked}\n")
    pip = [str(venv / "bin" / "python"), "-m", "pip", "-q"]
    subprocess.run([*pip, "install", "--no-deps", str(wheel)], check=True, capture_output=True,
                   timeout=600)  # fmt: skip
    r = subprocess.run([*pip, "check"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    cache = root / "cache"
    cache.mkdir()
    # The hole geometry this machine has built already (a content-hash cache): only saves
    # the convex decompositions, changes no result.
    holes = Path(os.environ.get("CFVS_CACHE") or Path.home() / ".cache" / "cfvs_maniskill")
    if (holes / "holes").is_dir():
        (cache / "holes").symlink_to(holes / "holes")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("VK_", "CFVS_"))}
    env.update(HOME=str(root / "home"), CFVS_CACHE=str(cache), PYTHONPATH="")
    work = root / "work"
    work.mkdir()
    return {"venv": venv, "env": env, "work": work}


def _run(user, *args: str, timeout: float = 900) -> subprocess.CompletedProcess:
    exe = args[0] if args[0].startswith("cfvs-") else "python"
    return subprocess.run(
        [str(user["venv"] / "bin" / exe), *args[exe != "python" :]],
        cwd=user["work"], env=user["env"], capture_output=True, text=True, timeout=timeout,
    )  # fmt: skip


def test_wheel_carries_what_a_user_needs_and_nothing_else(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    bundled = [n for n in names if "/bundled/" in n]
    for need in ("tasks/PegInsert6DoF.yaml", "sensors/realistic.yaml",
                 "assets/holes/cylinder.yaml", "assets/cad_parts/LICENSE.md",
                 "agents/cfvs/square/oakn.pt", "agents/cfvs/tasks.yaml",
                 "agents/kovis/round.pt"):  # fmt: skip
        assert f"cfvs_maniskill/bundled/{need}" in names
    shipped = {
        f"cfvs_maniskill/bundled/{p.relative_to(ROOT).as_posix()}"
        for p in (ROOT / "agents").rglob("*.pt")
        if "_stage1" not in p.name and ".step" not in p.name  # training intermediates
    }
    assert shipped <= set(bundled) and len(shipped) >= 10
    assert not [n for n in names if n.startswith(("results/", "tests/", "docs/"))]
    assert not [n for n in bundled if "_stage1" in n or n.endswith(".py")]
    assert "cfvs_maniskill_setup.py" in names
    assert wheel.stat().st_size < 20e6


def test_installed_package_runs_from_another_folder(user, tmp_path):
    # 0. Without a renderer the package imports, and making an env says which command sets
    # one up. (One test for the whole flow: the fresh environment takes minutes to install.)
    assert _run(user, "-c", "import cfvs_maniskill").returncode == 0
    r = _run(user, "-c", "import gymnasium as g, cfvs_maniskill; g.make('PegInsert6DoF-v1')")
    assert r.returncode != 0
    assert "RenderDeviceError" in r.stderr and "cfvs-maniskill setup-render" in r.stderr

    # 1. The renderer, as a user without apt access would: from a folder holding it.
    r = _run(user, "cfvs-maniskill", "setup-render",
             "--source", str(Path(sys.prefix) / "share" / "cfvs_maniskill" / "swiftshader"))  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert (Path(user["env"]["CFVS_CACHE"]) / "swiftshader" / "vk_swiftshader_icd.json").is_file()

    # 2. Every task registers and builds, from the bundled files.
    probe = (
        "import json, cfvs_maniskill as c, gymnasium as gym\n"
        "from cfvs_maniskill.rendering import device\n"
        "out = {'device': device.describe(), 'file': c.__file__, 'tasks': {}}\n"
        "for name, t in sorted(c.TASKS.items()):\n"
        "    env = gym.make(t.env_id, obs_mode='pointcloud')\n"
        "    obs, _ = env.reset(seed=1)\n"
        "    out['tasks'][name] = int(obs['pointcloud']['xyzw'].shape[1])\n"
        "    env.close()\n"
        "print(json.dumps(out))\n"
    )
    r = _run(user, "-c", probe)
    assert r.returncode == 0, r.stderr[-3000:]
    got = json.loads(r.stdout.strip().splitlines()[-1])
    assert str(user["venv"]) in got["file"] and "SwiftShader" in got["device"]
    assert set(got["tasks"]) == {p.stem for p in (ROOT / "tasks").glob("*.yaml")}
    assert all(n > 0 for n in got["tasks"].values())

    # 3. One CFVS episode with the shipped weights: the same record as from the checkout.
    args = ("cfvs_maniskill.run", "--task", "PegInsert3DoF", "--episodes", "1", "--seed", "500")
    r = _run(user, "-m", *args, "--out", "cfvs.jsonl")
    assert r.returncode == 0, r.stderr[-3000:]
    wheel_rec = json.loads((user["work"] / "cfvs.jsonl").read_text())
    r = run_cli(*args, "--out", str(tmp_path / "checkout.jsonl"))
    assert r.returncode == 0, r.stderr[-3000:]
    repo_rec = json.loads((tmp_path / "checkout.jsonl").read_text())
    assert wheel_rec["success"]
    for k in ("success", "object", "seed", "servo_time_s", "move_residuals"):
        assert wheel_rec[k] == repo_rec[k], k
    for k in ("weights", "sensor", "task", "object"):  # the same files, by the same names
        assert wheel_rec["provenance"][k] == repo_rec["provenance"][k], k
    version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    assert wheel_rec["provenance"]["code"] == version  # the installed version, not git

    # 4. A copied, edited task file and a folder of the user's own hole shapes, by path.
    holes = user["work"] / "my_holes"
    holes.mkdir()
    (holes / "my_block.yaml").write_text(BLOCK)
    text = (ROOT / "tasks" / "PegInsert3DoF.yaml").read_text()
    (user["work"] / "my_task.yaml").write_text(text + "objects: [my_block]\n")
    r = _run(user, "-m", "cfvs_maniskill.assets", "check", "my_holes")
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert "my_block" in r.stdout
    r = _run(user, "-m", "cfvs_maniskill.eval", "--out", "ev", "--tasks", "my_task.yaml",
             "--agents", "oracle", "cfvs", "--objects", "my_block", "--assets", "my_holes",
             "--episodes-per-object", "1", "--init-errors", "small", "--workers", "1")  # fmt: skip
    assert r.returncode == 0, r.stderr[-3000:]
    r = _run(user, "-m", "cfvs_maniskill.report", "ev", "--out", "rep", "--assets", "my_holes",
             "--no-videos")  # fmt: skip
    assert r.returncode == 0, r.stderr[-3000:]
    report = (user["work"] / "rep" / "README.md").read_text()
    assert "### my_task" in report and "my_block" in report
    assert "| cfvs | my_task | ideal | 1 |" in report
