"""Evaluation as a careless or hostile user meets it: YAML that expands without bound, agents
that raise, changed settings, two writers on one folder, damaged or odd files. Each ends
in a named error or a recorded failure; none in a traceback, a hang or a lost record."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from cfvs_maniskill import resources
from cfvs_maniskill.errors import FileFieldError

from .conftest import ROOT, run_cli

BOMB = "\n".join(
    ['a: &a ["x", "x", "x", "x", "x", "x", "x", "x", "x"]']
    + [
        f"{c}: &{c} [{', '.join([f'*{p}'] * 9)}]"
        for p, c in zip("abcdefgh", "bcdefghi", strict=True)
    ]
)
"""Nine lines whose aliases expand to 9^9 values."""

HOSTILE_YAML = {
    "alias bomb": (BOMB, "anchors and aliases"),
    "one alias": ("dof: &d 3\nclearance: *d\n", "anchors and aliases"),
    "deep nesting": ("x: " + "[" * 5000 + "]" * 5000 + "\n", "nested more than"),
    "many values": ("x: [" + ", ".join(["1"] * 20000) + "]\n", "more than 10000 values"),
    "huge file": ("# " + "x" * (2 << 20) + "\n", "a file of at most"),
    "huge integer": ("dof: " + "9" * 5000 + "\n", "integer"),
    "not text": (b"\xff\xfe\x00dof", "not UTF-8"),
}


def _load(kind: str, path: Path):
    """Read `path` as a user file of `kind` the way the package does."""
    if kind == "task":
        from cfvs_maniskill.envs.lookup import find_task

        return find_task(str(path))
    if kind == "sensor":
        from cfvs_maniskill.sensing.profile import load_profile

        return load_profile(str(path))
    if kind == "hole":
        from cfvs_maniskill.objects.spec import load_spec

        return load_spec(path)
    from cfvs_maniskill.policies.cfvs.agent import weights_for

    return weights_for("PegInsert3DoF", "square", path.parent)


@pytest.mark.parametrize("kind", ["task", "sensor", "hole", "weights table"])
@pytest.mark.parametrize("case", list(HOSTILE_YAML))
def test_hostile_yaml_is_a_named_error_for_every_file_kind(kind, case, tmp_path):
    """Bounded before anything walks it: an error naming the file and what is wrong."""
    text, words = HOSTILE_YAML[case]
    path = tmp_path / ("tasks.yaml" if kind == "weights table" else "my_file.yaml")
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(FileFieldError) as e:
        _load(kind, path)
    assert str(path) in str(e.value) and words in str(e.value), str(e.value)[:300]


def test_a_weights_table_missing_a_net_names_the_field(tmp_path):
    from cfvs_maniskill.policies.cfvs.agent import weights_for

    (tmp_path / "tasks.yaml").write_text("PegInsert3DoF: {oakn: square/oakn.pt}\n")
    with pytest.raises(FileFieldError, match=r"tasks.yaml: field 'PegInsert3DoF.opn'"):
        weights_for("PegInsert3DoF", "square", tmp_path)


def test_weights_holding_nan_are_refused_naming_the_parameter(tmp_path):
    from cfvs_maniskill.nets.checkpoint import WeightsError
    from cfvs_maniskill.policies.kovis.agent import WEIGHTS_DIR
    from cfvs_maniskill.policies.networks import load_weights

    blob = torch.load(WEIGHTS_DIR / "square.pt", weights_only=True)
    name = next(iter(blob["state_dict"]))
    blob["state_dict"][name] = blob["state_dict"][name] * float("nan")
    torch.save(blob, tmp_path / "square.pt")
    with pytest.raises(WeightsError, match=rf"parameter '{name}' holds NaN"):
        load_weights(tmp_path / "square.pt", "kovis", "square")


def test_import_with_a_bomb_in_the_user_folder_and_an_unwritable_home(tmp_path):
    """An alias bomb among the user's task files: the package imports (the file left out,
    named); HOME a plain file, so nothing can be written under it: import still works and
    writes nothing."""
    home = tmp_path / "home"
    (home / "tasks").mkdir(parents=True)
    (home / "tasks" / "bomb.yaml").write_text(BOMB)
    not_a_dir = tmp_path / "home_is_a_file"
    not_a_dir.write_text("")
    before = sorted(tmp_path.rglob("*"))
    env = {**os.environ, "CFVS_HOME": str(home), "HOME": str(not_a_dir), "CFVS_CACHE": ""}
    env["MPLCONFIGDIR"] = str(tmp_path / "mpl")  # matplotlib's own cache (imported by SAPIEN)
    r = subprocess.run(
        [sys.executable, "-c", "import cfvs_maniskill, cfvs_maniskill.robots.ur5"],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr[-2000:]
    assert "bomb.yaml" in r.stderr and "anchors and aliases" in r.stderr, r.stderr[-2000:]
    after = [p for p in sorted(tmp_path.rglob("*")) if not p.is_relative_to(tmp_path / "mpl")]
    assert after == before, "import wrote files"


def test_the_cache_falls_back_to_a_writable_folder(tmp_path, monkeypatch):
    home_file = tmp_path / "home"
    home_file.write_text("")
    monkeypatch.setenv("HOME", str(home_file))
    monkeypatch.delenv("CFVS_CACHE", raising=False)
    root = resources.cache_root()
    assert not root.is_relative_to(home_file)
    root.mkdir(parents=True, exist_ok=True)
    monkeypatch.setenv("CFVS_CACHE", str(tmp_path / "c"))
    assert resources.cache_root() == tmp_path / "c"


def test_a_symlink_loop_is_named_and_the_file_beside_it_still_loads(tmp_path):
    from cfvs_maniskill.objects.library import load_library

    shutil.copy(ROOT / "assets" / "holes" / "cylinder.yaml", tmp_path / "my_cylinder.yaml")
    (tmp_path / "a.yaml").symlink_to(tmp_path / "b.yaml")
    (tmp_path / "b.yaml").symlink_to(tmp_path / "a.yaml")
    lib = load_library([tmp_path], include_default=False)
    assert list(lib.specs) == ["my_cylinder"]
    assert any("a.yaml" in str(e) and "<file>" in str(e) for e in lib.errors), lib.errors


def test_a_user_hole_file_named_like_a_bundled_one_is_said(tmp_path):
    from cfvs_maniskill.objects.library import load_library

    shutil.copy(ROOT / "assets" / "holes" / "cylinder.yaml", tmp_path / "cylinder.yaml")
    with pytest.warns(UserWarning, match=r"cylinder.yaml.*already defined by.*not used"):
        lib = load_library([tmp_path])
    assert lib.specs["cylinder"].source != str(tmp_path / "cylinder.yaml")


# --- the evaluation's folder --------------------------------------------------------------

EVAL = [
    "--tasks", "PegInsert3DoF", "--objects", "cuboid_test_1", "--init-errors", "small",
    "--episodes-per-object", "2", "--workers", "1",
]  # fmt: skip


def _cli(module: str, *args: str, capsys) -> tuple[int, str, str]:
    """(exit code, stdout, stderr) of a command run in this process: the refusals below
    end before any worker or env starts, so a fresh interpreter would only add its import."""
    import tyro

    mod = __import__(f"cfvs_maniskill.{module}", fromlist=["main"])
    spec = mod.EvalArgs if module == "eval.__main__" else mod.RunArgs
    try:
        code = mod.main(tyro.cli(spec, args=list(args)))
        code = code if isinstance(code, int) else 0
    except SystemExit as e:
        code = e.code
    out = capsys.readouterr()
    return code, out.out, out.err


def _lines(path: Path) -> list[dict]:
    return [json.loads(x) for x in path.read_text().splitlines() if x.strip()]


@pytest.fixture(scope="module")
def faulty_eval(tmp_path_factory) -> Path:
    """One evaluation of three agents with bugs and the oracle, in worker processes."""
    out = tmp_path_factory.mktemp("faulty")
    agents = [f"tests.crashing_agent:{c}" for c in ("RaisingAgent", "BrokenInitAgent", "NoneAgent")]
    r = run_cli("cfvs_maniskill.eval", *EVAL, "--agents", *agents, "oracle", "--out", str(out))
    assert r.returncode == 0, r.stderr[-3000:]
    return out


def test_an_agents_failure_is_its_episodes_failure_and_the_evaluation_goes_on(faulty_eval):
    recs = {(r["agent"], r["episode"]): r for r in _lines(faulty_eval / "episodes.jsonl")}
    assert len(recs) == 8, sorted(recs)
    expected = {
        "RaisingAgent": (1, "KeyError"),
        "BrokenInitAgent": (0, "RuntimeError"),
        "NoneAgent": (1, "MalformedAction"),
    }
    for (agent, _), rec in recs.items():
        name = agent.rpartition(":")[2]
        if name == "oracle":
            assert rec["success"] and rec["agent_error"] is None
            continue
        decision, kind = expected[name]
        assert not rec["success"] and not rec.get("crashed")
        assert rec["agent_error"]["decision"] == decision and rec["agent_error"]["type"] == kind
        assert rec["provenance"]["code_fingerprint"]  # a whole record, from the env
    summary = (faulty_eval / "summary.md").read_text()
    assert "6 episodes failed on an agent's own error" in summary
    assert "cannot open the calibration file" in summary


def test_the_report_counts_and_lists_agent_errors(faulty_eval, tmp_path):
    from cfvs_maniskill.report import tables
    from cfvs_maniskill.report.load import load_records

    records = load_records(faulty_eval)
    assert sum(not r["success"] for r in records) == 6
    listed = tables.table_agent_errors(records)
    assert listed.startswith("6 episodes, counted as failures")
    assert "KeyError" in listed and "RuntimeError" in listed and "MalformedAction" in listed


@pytest.mark.parametrize(
    "change, words",
    [
        (["--seed", "7"], "--seed: job PegInsert3DoF|"),
        (["--search-radius", "0"], "--search-radius: the records have"),
        (["--sensors", "SENSOR_FILE"], "sensor 'ideal': its file"),
    ],
)
def test_resuming_with_other_settings_is_refused_naming_them(
    faulty_eval, tmp_path, change, words, capsys
):
    """A finished folder asked again with another base seed, search radius or sensor file of
    the same name: exit 2 naming the difference; nothing appended."""
    out = tmp_path / "out"
    shutil.copytree(faulty_eval, out)
    sensor = tmp_path / "ideal.yaml"  # another profile saved under the name ideal
    text = (ROOT / "sensors" / "ideal.yaml").read_text()
    sensor.write_text(text + "\n# another calibration\n")
    change = [str(sensor) if c == "SENSOR_FILE" else c for c in change]
    before = (out / "episodes.jsonl").read_bytes()
    code, _, err = _cli(
        "eval.__main__", *EVAL, "--agents", "oracle", "--out", str(out), *change, capsys=capsys
    )
    assert code == 2, err[-2000:]
    assert "holds records made with other settings" in err and words in err, err
    assert (out / "episodes.jsonl").read_bytes() == before


def test_one_evaluation_at_a_time_and_a_killed_one_leaves_no_lock(faulty_eval, capsys):
    from cfvs_maniskill.eval.results import ResultsError, exclusive

    path = faulty_eval / "episodes.jsonl"
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time\n"
         "from pathlib import Path\n"
         "from cfvs_maniskill.eval.results import exclusive\n"
         f"with exclusive(Path({str(path)!r})):\n"
         "    print('held', flush=True); time.sleep(600)"],
        cwd=ROOT, stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "held"
        code, _, err = _cli(
            "eval.__main__", *EVAL, "--agents", "oracle", "--out", str(faulty_eval), capsys=capsys
        )
        assert code == 2 and f"process {holder.pid} is writing" in err, err
        with pytest.raises(ResultsError, match="is writing these results"), exclusive(path):
            pass
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
    with exclusive(path):  # the kernel dropped the killed holder's lock
        pass


def test_run_out_twice_records_each_episode_once(tmp_path, capsys):
    out = tmp_path / "run.jsonl"
    args = ["--task", "PegInsert3DoF", "--agent", "oracle", "--episodes", "2", "--out", str(out)]
    assert _cli("run", *args, capsys=capsys)[0] == 0
    code, stdout, err = _cli("run", *args[:-3], "3", "--out", str(out), capsys=capsys)
    assert code == 0, err[-2000:]
    assert "2 of the 3 episodes are in" in stdout
    keys = [rec["key"] for rec in _lines(out)]
    assert len(keys) == 3 == len(set(keys))


@pytest.mark.parametrize("damage", ["corrupt gz", "results is a folder", "out is a file"])
def test_damaged_results_folders_are_named(faulty_eval, tmp_path, damage, capsys):
    from cfvs_maniskill.eval.results import ResultsError, append, read_done

    out = tmp_path / "out"
    if damage == "out is a file":
        out.write_text("")
        code, _, err = _cli(
            "eval.__main__", *EVAL, "--agents", "oracle", "--out", str(out), capsys=capsys
        )
        assert code == 2 and f"--out {out}: cannot be a results folder" in err, err
        return
    shutil.copytree(faulty_eval, out)
    path = out / "episodes.jsonl"
    if damage == "corrupt gz":
        (out / "episodes.jsonl.gz").write_bytes(b"\x1f\x8b\x08not gzip at all")
        with pytest.raises(ResultsError, match=r"episodes.jsonl.gz: not a compressed results"):
            read_done(path)
    else:
        path.unlink()
        path.mkdir()  # unwritable as a file whoever runs it (root ignores permissions)
        with pytest.raises(ResultsError, match="cannot"):
            read_done(path)
        with pytest.raises(ResultsError, match="cannot write results"):
            append(path, {"key": "x"})


def test_a_grid_too_large_is_refused_before_it_is_built(capsys):
    code, _, err = _cli(
        "eval.__main__", "--tasks", "PegInsert3DoF", "--agents", "oracle",
        "--episodes-per-object", "10000000", "--out", "/nonexistent/never/written", capsys=capsys,
    )  # fmt: skip
    assert code == 2 and "jobs; one evaluation takes at most 100000" in err, err
    assert not Path("/nonexistent").exists()  # (10^8 jobs built first would not fit in memory)
