"""`report` names what it cannot read instead of dropping it or crashing half-way, and a
report folder is never left half-written."""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import pytest

from .conftest import run_cli

ROOT = Path(__file__).resolve().parent.parent


def records(n: int = 6) -> list[dict]:
    with gzip.open(ROOT / "results/cfvs_ablations/episodes.jsonl.gz", "rt") as f:
        return [json.loads(next(f)) for _ in range(n)]


def write(folder: Path, lines: list[str]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "episodes.jsonl"
    path.write_text("\n".join(lines) + "\n")
    return path


def report(results: Path, out: Path):
    return run_cli("cfvs_maniskill.report", str(results), "--out", str(out), "--no-videos")


def test_a_damaged_line_in_the_middle_is_named_and_nothing_is_written(tmp_path):
    lines = [json.dumps(r) for r in records()]
    lines[2] = lines[2][:40]  # cut mid-record, not the last line
    path = write(tmp_path / "run", lines)
    r = report(tmp_path / "run", tmp_path / "out")
    assert r.returncode == 2, r.stdout + r.stderr
    assert f"{path}:3: not a result record" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("bad", [float("nan"), "yes", None])
def test_a_success_that_is_not_true_or_false_is_named_with_its_field(tmp_path, bad):
    recs = records()
    recs[4]["success"] = bad
    path = write(tmp_path / "run", [json.dumps(r) for r in recs])
    r = report(tmp_path / "run", tmp_path / "out")
    assert r.returncode == 2, r.stdout + r.stderr
    assert f"{path}:5: field `success` is {bad!r}: expected true or false" in r.stderr
    assert "Traceback" not in r.stderr and not (tmp_path / "out").exists()


def test_a_torn_last_line_of_a_running_evaluation_is_left_out_with_a_note(tmp_path):
    lines = [json.dumps(r) for r in records()]
    lines[-1] = lines[-1][:30]
    path = write(tmp_path / "run", lines)
    r = report(tmp_path / "run", tmp_path / "out")
    assert r.returncode == 0, r.stdout + r.stderr
    assert f"{path}:6: a torn last line left out" in r.stdout
    assert "(5 episodes)" in (tmp_path / "out" / "README.md").read_text()
    assert not list((tmp_path / "out").glob(".*.tmp"))
