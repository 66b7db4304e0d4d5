"""The README stays a guide (short, the two commands first) and no relative link in the
documentation points at a file that does not exist."""

from __future__ import annotations

import re
from pathlib import Path

from .conftest import run_cli

ROOT = Path(__file__).resolve().parent.parent
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), *ROOT.glob("agents/*/README.md")]


def test_readme_is_short_and_starts_with_the_two_commands():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 150
    blocks = re.findall(r"```bash\n(.*?)```", text, flags=re.S)
    assert (
        "scripts/setup.sh" in blocks[0] and "cfvs_maniskill.run --task PegInsert6DoF" in blocks[0]
    )
    assert blocks[1].strip() == "bash scripts/test.sh"
    assert (ROOT / ".ci" / "run").read_text().count("scripts/test.sh") >= 1


HASH = re.compile(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b")
ROUND = re.compile(r"\bsessions? \d+", re.I)


def test_readme_and_docs_are_a_guide_not_a_diary():
    """No commit hash in the README, no numbered round of past work in it or docs/, a
    picture of an insertion, and docs/ short enough to read in an afternoon."""
    readme = (ROOT / "README.md").read_text()
    assert not HASH.findall(readme), HASH.findall(readme)
    assert re.search(r"!\[[^]]*\]\((docs/images/[^)]+\.(gif|png))\)", readme)
    diary = [f"{d.relative_to(ROOT)}: {m}" for d in DOCS for m in ROUND.findall(d.read_text())]
    assert not diary, diary[:10]
    words = sum(len(d.read_text().split()) for d in (ROOT / "docs").glob("*.md"))
    assert words <= 15_000, words


def test_every_relative_link_resolves():
    broken = []
    for doc in DOCS:
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", doc.read_text()):
            if "://" not in target and not (doc.parent / target).exists():
                broken.append(f"{doc.relative_to(ROOT)} -> {target}")
    assert not broken, broken


def records_without_provenance(root: Path) -> list[str]:
    """`file:line` of every result record below `root` (plain or gzipped JSON lines) that
    does not say which code made it."""
    import gzip
    import json

    missing = []
    for f in sorted([*root.rglob("*.jsonl"), *root.rglob("*.jsonl.gz")]):
        if f.suffix == ".gz":
            with gzip.open(f, "rt") as g:
                text = g.read()
        else:
            text = f.read_text()
        for i, line in enumerate(text.splitlines()):
            if line.strip() and not (json.loads(line).get("provenance") or {}).get("code"):
                missing.append(f"{f.relative_to(root)}:{i + 1}")
    return missing


def test_every_committed_record_carries_provenance():
    """Every result record in the repository says what made it: its own provenance, or one
    reconstructed from git (docs/evaluation.md)."""
    files = [*(ROOT / "results").rglob("*.jsonl.gz")]
    headline = [f"headline/{k}" for k in ("main", "plain", "cameras", "cameras_plain")]
    for folder in (*headline, "headline_tight"):
        gz = ROOT / "results" / folder / "episodes.jsonl.gz"
        assert gz in files, f"{gz}: the committed records are gzipped JSON lines"
    missing = records_without_provenance(ROOT / "results")
    assert not missing, missing[:10]


def test_a_record_without_provenance_is_found(tmp_path):
    """The check above reads what is committed: one record stripped of its provenance in a
    copy of a committed file is named, by file and line."""
    import gzip
    import json

    src = next((ROOT / "results").rglob("*.jsonl.gz"))
    with gzip.open(src, "rt") as f:
        recs = [json.loads(x) for x in f.read().splitlines() if x.strip()]
    recs[3].pop("provenance")
    with gzip.open(tmp_path / "episodes.jsonl.gz", "wt") as f:
        f.write("\n".join(json.dumps(r) for r in recs) + "\n")
    assert records_without_provenance(tmp_path) == ["episodes.jsonl.gz:4"]


def test_readme_numbers_come_from_current_records_of_one_provenance():
    """`report --check` on the committed results: every headline cell of one code version
    and made with today's weights, sensor, task and hole files; the README's table is what
    the records give. Changing a weights or sensor file without re-running fails here."""
    r = run_cli("cfvs_maniskill.report", "results", "--check", "--readme", "README.md")
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
