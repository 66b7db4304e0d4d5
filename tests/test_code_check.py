"""Records know the code that made them (provenance.code_fingerprint), and `report --check`
finds README cells whose records another version of the episode code made."""

from __future__ import annotations

from pathlib import Path

from cfvs_maniskill.provenance import PACKAGE_DIR, code_fingerprint, fingerprint

ROOT = Path(__file__).resolve().parent.parent


def sources(change: dict[str, tuple[str, str]] | None = None) -> list[tuple[str, bytes]]:
    """The package's sources as (path, bytes), with `change` {path: (old, new)} applied."""
    out = []
    for f in sorted(PACKAGE_DIR.rglob("*.py")):
        rel = f.relative_to(PACKAGE_DIR).as_posix()
        src = f.read_text()
        if change and rel in change:
            old, new = change[rel]
            assert old in src, (rel, old)
            src = src.replace(old, new, 1)
        out.append((rel, src.encode()))
    return out


def test_the_fingerprint_is_the_running_code_and_moves_only_with_what_runs():
    assert fingerprint(sources()) == code_fingerprint()
    # A comment, a docstring or a line break in episode code: the same code runs.
    same = {
        "envs/scene.py": ('"""How far the peg', '"""How deep the peg'),
        "constants.py": (
            "SUCCESS_TIP_TOLERANCE = 0.005",
            "SUCCESS_TIP_TOLERANCE = (\n    0.005\n)",
        ),
    }
    assert fingerprint(sources(same)) == code_fingerprint()
    # A changed number in an agent: another decision, another fingerprint.
    moved = {"policies/cfvs/agent.py": ("MAX_TURNS = 3", "MAX_TURNS = 2")}
    assert fingerprint(sources(moved)) != code_fingerprint()
    # The report's code never runs in an episode.
    report = {"report/tables.py": ('INITS = ("small", "large")', 'INITS = ("large", "small")')}
    assert fingerprint(sources(report)) == code_fingerprint()


def test_check_names_the_cells_a_branch_changing_an_agent_leaves_stale(monkeypatch, capsys):
    """The README's records, checked as a branch that changed CFVS's wrist turn without
    re-running would check them: exit 1, every CFVS cell named stale; the same branch with
    only a docstring changed passes."""
    from cfvs_maniskill.report import trace
    from cfvs_maniskill.report.__main__ import check
    from cfvs_maniskill.report.load import load_records

    records = load_records(ROOT / "results")
    assert check(records, [], ROOT / "README.md") == 0, capsys.readouterr().out[-2000:]
    capsys.readouterr()

    branch = fingerprint(sources({"policies/cfvs/agent.py": ("MAX_TURNS = 3", "MAX_TURNS = 2")}))
    monkeypatch.setattr(trace, "code_fingerprint", lambda: branch)
    assert check(records, [], None) == 1
    out = capsys.readouterr().out
    assert "cfvs PegInsert6DoF realistic large: stale: episode code changed since" in out, out
    assert "NOT today's episode code" in out

    docs_only = fingerprint(
        sources(
            {"policies/cfvs/config.py": ('"""The config of ablation `name`', '"""Ablation `name`')}
        )
    )
    monkeypatch.setattr(trace, "code_fingerprint", lambda: docs_only)
    assert check(records, [], None) == 0


def test_the_version_is_written_once_so_a_release_leaves_records_current():
    """`__version__` is the installed metadata's, i.e. pyproject.toml's: a release bumps
    no episode code, so the records made just before it stay current."""
    import tomllib

    import cfvs_maniskill

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert cfvs_maniskill.__version__ == project["version"]
