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
    assert len(text.splitlines()) <= 250
    blocks = re.findall(r"```bash\n(.*?)```", text, flags=re.S)
    assert (
        "scripts/setup.sh" in blocks[0] and "cfvs_maniskill.run --task PegInsert6DoF" in blocks[0]
    )
    assert blocks[1].strip() == "bash scripts/test.sh"
    assert (ROOT / ".ci" / "run").read_text().count("scripts/test.sh") >= 1


def test_every_relative_link_resolves():
    broken = []
    for doc in DOCS:
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", doc.read_text()):
            if "://" not in target and not (doc.parent / target).exists():
                broken.append(f"{doc.relative_to(ROOT)} -> {target}")
    assert not broken, broken


def test_every_committed_record_carries_provenance():
    """Every result record in the repository says what made it: its own provenance, or one
    reconstructed from git (docs/evaluation.md)."""
    missing = []
    for f in sorted((ROOT / "results").rglob("*.jsonl")):
        for i, line in enumerate(f.read_text().splitlines()):
            if line.strip() and '"provenance": {"code": ' not in line:
                missing.append(f"{f.relative_to(ROOT)}:{i + 1}")
    assert not missing, missing[:10]


def test_readme_numbers_come_from_current_records_of_one_provenance():
    """`report --check` on the committed results: every headline cell of one code version
    and made with today's weights, sensor, task and hole files; the README's table is what
    the records give. Changing a weights or sensor file without re-running fails here."""
    r = run_cli("cfvs_maniskill.report", "results", "--check", "--readme", "README.md")
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
