"""A frozen set's records are written once, by its release's run, and never re-run or
replaced (docs/evaluation.md): every committed file under a frozen set's results folder is
byte for byte what the commit that added it wrote."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from cfvs_maniskill.eval.results import FROZEN_RESULTS

ROOT = Path(__file__).resolve().parent.parent


def git(*args: str, text: bool = True):
    return subprocess.run(
        ["git", "-C", str(ROOT), *args], capture_output=True, text=text, check=True
    ).stdout


def changed_since_added(path: str, content: bytes | None = None) -> str | None:
    """None when the file (or `content` in its place) is what the commit that added it
    wrote, else why not."""
    added = git("log", "--diff-filter=A", "--format=%H", "--", path).split()
    if not added:
        return f"{path}: no commit adds it (git history missing?)"
    first = added[-1]
    if content is None:
        content = (ROOT / path).read_bytes()
    if git("show", f"{first}:{path}", text=False) != content:
        return f"{path}: differs from what {first[:12]} added"
    return None


def frozen_files() -> list[str]:
    return git("ls-files", "--", *FROZEN_RESULTS).split()


def test_every_frozen_sets_records_are_what_their_release_wrote():
    files = frozen_files()
    assert len(files) >= 8, files  # releases v1 and v2 of the final set, the generalisation runs
    problems = [p for f in files if (p := changed_since_added(f))]
    assert not problems, problems


def test_the_check_catches_a_frozen_record_rewritten_after_its_release():
    """What the final set's v2 re-run did (its 0.5 mm D405 cell replaced after the release):
    the file it wrote is refused, and so is any other change to a frozen file."""
    path = "results/final/v2/episodes.jsonl.gz"
    rerun = git("show", f"c741365:{path}", text=False)  # the re-run, before the restore
    assert "differs from what e466508" in changed_since_added(path, rerun)
    original = (ROOT / path).read_bytes()
    assert changed_since_added(path, original + b"\n") is not None
    assert changed_since_added(path, original) is None


@pytest.mark.parametrize("release", ["v2", "v2-search0"])
def test_the_final_sets_release_v2_is_its_own_run_and_the_rerun_is_labelled(release):
    """The wrist-turn re-run of release v2's 0.5 mm D405 cell lives in a development folder
    and names itself so; release v2's folder holds its one run (code 7e892fb)."""
    import gzip
    import json

    with gzip.open(ROOT / f"results/final/{release}/episodes.jsonl.gz", "rt") as f:
        recs = [json.loads(x) for x in f]
    assert {r["provenance"]["code"][:7] for r in recs} == {"7e892fb"}
    dev = ROOT / f"results/final_rerun_dev/{release}"
    assert "development re-run, not the frozen release" in (dev / "summary.md").read_text()
