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


def check_as_if_today(monkeypatch, change: dict[str, tuple[str, str]]) -> int:
    """`report --check` on the README's records with today's checkout carrying `change`
    (sources() above), as a branch that made it without re-running would check them."""
    from cfvs_maniskill.report import trace
    from cfvs_maniskill.report.__main__ import check
    from cfvs_maniskill.report.load import load_records

    branch = dict(sources(change))
    whole = fingerprint(branch.items())
    monkeypatch.setattr(trace, "code_fingerprint", lambda: whole)
    monkeypatch.setattr(trace, "_sources_today", lambda: branch)
    trace._module_fingerprint_at.cache_clear()
    try:
        return check(load_records(ROOT / "results"), [], None)
    finally:
        trace._module_fingerprint_at.cache_clear()


def stale_agents(out: str) -> set[str]:
    return {ln.split()[0] for ln in out.splitlines() if ": stale: episode code changed" in ln}


def test_check_names_the_cells_a_branch_changing_an_agent_leaves_stale(monkeypatch, capsys):
    """The README's records, checked as a branch that changed CFVS's wrist turn without
    re-running would check them: exit 1, every CFVS cell named stale, and the agents that
    import CFVS (icp, icp_kpts start from its coarse stage); KOVIS, 3DRHD and the oracle
    run none of that code and stay current. A change to the env stales every agent; a
    docstring none."""
    from cfvs_maniskill.report.__main__ import check
    from cfvs_maniskill.report.load import load_records

    records = load_records(ROOT / "results")
    assert check(records, [], ROOT / "README.md") == 0, capsys.readouterr().out[-2000:]
    capsys.readouterr()

    turn = {"policies/cfvs/agent.py": ("MAX_TURNS = 3", "MAX_TURNS = 2")}
    assert check_as_if_today(monkeypatch, turn) == 1
    out = capsys.readouterr().out
    assert "cfvs PegInsert6DoF realistic large: stale: episode code changed since" in out, out
    assert "NOT today's episode code" in out
    assert stale_agents(out) == {"cfvs", "cfvs_plain", "icp", "icp_kpts"}, stale_agents(out)

    env = {"envs/peg_insert.py": ("MAX_INIT_TRIES = 100", "MAX_INIT_TRIES = 99")}
    assert check_as_if_today(monkeypatch, env) == 1
    stale = stale_agents(capsys.readouterr().out)
    assert {"cfvs", "kovis", "3drhd", "oracle", "icp"} <= stale, stale

    docs_only = {"policies/cfvs/config.py": ('"""The config of ablation `name`', '"""Ablation')}
    assert check_as_if_today(monkeypatch, docs_only) == 0


def test_records_of_uncommitted_edits_elsewhere_agree_with_clean_records_of_that_code():
    """A record made with uncommitted edits (`+dirty`) whose episode code is its commit's
    (the edits lay in docs or the report) has the same signature as a clean record of
    that commit, so their cell is not called mixed; one whose episode code differs has
    another."""
    import subprocess

    from cfvs_maniskill.report import trace

    head = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--short=12", "HEAD"],
        capture_output=True, text=True, check=True,
    ).stdout.strip()  # fmt: skip
    files = {"weights": {"agents/cfvs/round/oakn.pt": "0" * 64}, "sensor": {"sha256": "1"}}
    same = trace.fingerprint_at(head)
    assert same is not None

    def record(code: str, fingerprint: str | None = None) -> dict:
        made = {"code": code, **files} | ({"code_fingerprint": fingerprint} if fingerprint else {})
        return {"agent": "cfvs", "task": "PegInsert3DoF", "provenance": made}

    clean, dirty = record(head), record(f"{head}+dirty", same)
    edited = record(f"{head}+dirty", "0" * 16)
    sig = trace.signature(trace.resolve(clean))
    assert trace.signature(trace.resolve(dirty)) == sig
    assert trace.signature(trace.resolve(edited)) != sig
    assert not any(why.startswith("mixed") for why in trace.cell_status([clean, dirty])[1])
    assert any(why.startswith("mixed") for why in trace.cell_status([clean, edited])[1])


def test_every_module_of_episode_code_is_in_some_agents_scope():
    """An agent's scope follows the package's import statements (report/scope.py); a module
    no agent's episodes import (reached some other way, by a name in a string) would leave
    every record current when it changes. Only tools run by no episode are outside."""
    from cfvs_maniskill.policies.registry import AGENTS
    from cfvs_maniskill.provenance import is_episode_code
    from cfvs_maniskill.report.scope import agent_scope

    src = dict(sources())
    scopes = {a: agent_scope(src, e.cls.split(":")[0]) for a, e in AGENTS.items()}
    reached = set().union(*scopes.values())
    tools = {"assets.py", "tool.py", "stats.py", "objects/meshes.py"}  # CLIs, asset scripts
    assert {p for p in src if is_episode_code(p)} - reached == tools
    assert "perception/rim.py" in scopes["cfvs"] and "perception/rim.py" not in scopes["kovis"]
    assert "sensing/depth.py" in scopes["kovis"] and "control/executor.py" in scopes["oracle"]
    assert agent_scope(src, "my_pkg.my_agent") is None  # your own agent: all the code


def test_the_version_is_written_once_so_a_release_leaves_records_current():
    """`__version__` is the installed metadata's, i.e. pyproject.toml's: a release bumps
    no episode code, so the records made just before it stay current."""
    import tomllib

    import cfvs_maniskill

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert cfvs_maniskill.__version__ == project["version"]
