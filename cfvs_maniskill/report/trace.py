"""Which code and files each table cell comes from, and whether it is still what today's
code and files would give: a cell is *mixed* when its records differ in code, weights,
sensor profile or task file, and *stale* when they were made with episode code,
weights, a sensor profile, a task or hole file that is not today's (or with no provenance
at all). The episode code is that which the record's agent can run (report/scope.py),
compared with git's copy at the record's commit; a record of uncommitted code is compared
on all of it (provenance.code_fingerprint).

Records made before records carried provenance have a reconstructed one, `{"code":
COMMIT, "reconstructed": "git"}`: COMMIT added the record to the repository (the code that
made it is that commit or an earlier one), and its files are those at today's paths as
they were in COMMIT, read from git when a report needs them (`resolve`)."""

from __future__ import annotations

import functools
import hashlib
import json
import subprocess
from collections import Counter
from dataclasses import replace
from pathlib import Path

from cfvs_maniskill import resources
from cfvs_maniskill.constants import PROJECT_ROOT
from cfvs_maniskill.provenance import PACKAGE_DIR, code_fingerprint, fingerprint, sha256
from cfvs_maniskill.report.scope import scoped_fingerprint


def _git(*args: str, text: bool = True):
    return subprocess.run(
        ["git", "-C", str(PROJECT_ROOT), *args], capture_output=True, text=text, check=True
    ).stdout


@functools.cache
def _tree(commit: str) -> dict[str, str]:
    """path -> blob id of the files an episode depends on, in `commit`."""
    listing = _git("ls-tree", "-r", commit, "--", "agents", "sensors", "tasks", "assets")
    return {ln.split("\t", 1)[1]: ln.split()[2] for ln in listing.splitlines()}


@functools.cache
def _blob_sha256(blob: str) -> str:
    return hashlib.sha256(_blob(blob)).hexdigest()


def _at(commit: str, path: str) -> str:
    blob = _tree(commit).get(path)
    return _blob_sha256(blob) if blob else f"absent in {commit}"


@functools.cache
def _hole_files() -> dict[str, tuple[str, ...]]:
    """Hole object name -> its files (today's paths), over every bundled folder."""
    from cfvs_maniskill.objects.library import load_library
    from cfvs_maniskill.provenance import file_key

    dirs = [d for d in sorted(resources.bundled("assets").iterdir()) if d.is_dir()]
    lib = load_library(dirs, include_default=False)
    return {
        n: (file_key(s.source), *([file_key(s.mesh_file)] if s.mesh_file else []))
        for n, s in lib.specs.items()
    }


@functools.cache
def _sources_at(code: str) -> dict[str, bytes] | None:
    """The package's modules (path in the package -> source) at commit `code` (a record's
    `code`: `git describe` output or a hash), None where git cannot give them (not a commit
    here, or `+dirty`)."""
    if "+" in code:
        return None
    commit = code.rsplit("-g", 1)[-1]  # `git describe`: TAG-N-gHASH
    try:
        listing = _git("ls-tree", "-r", commit, "--", PACKAGE_DIR.name)
    except (OSError, subprocess.CalledProcessError):
        return None
    sources = {}
    for ln in listing.splitlines():
        meta, path = ln.split("\t", 1)
        if meta.split()[1] == "blob" and path.endswith(".py"):
            sources[path.split("/", 1)[1]] = _blob(meta.split()[2])
    return sources


@functools.cache
def fingerprint_at(code: str) -> str | None:
    """The episode code's fingerprint at commit `code`, None where git cannot give it."""
    sources = _sources_at(code)
    return None if sources is None else fingerprint(sources.items())


@functools.cache
def _sources_today() -> dict[str, bytes]:
    return {
        f.relative_to(PACKAGE_DIR).as_posix(): f.read_bytes() for f in PACKAGE_DIR.rglob("*.py")
    }


@functools.cache
def agent_module(agent: str) -> str | None:
    """The module (dotted) defining agent `agent`'s class, None when it cannot be named."""
    from cfvs_maniskill.policies.registry import _entry

    try:
        return _entry(agent).cls.split(":", 1)[0]
    except KeyError:
        return None


def agent_fingerprint_at(code: str | None, agent: str) -> str | None:
    """The fingerprint of the episode code `agent`'s episodes can run (report/scope.py) at
    commit `code` (None: today's checkout); None where git cannot give the code."""
    return _module_fingerprint_at(code, agent_module(agent))


def _agent_fingerprint_of(p: dict, agent: str) -> str | None:
    """`agent_fingerprint_at` the record's commit; for a record made with uncommitted edits
    (`+dirty`) whose episode code was still its commit's, or is today's (the edits lay
    elsewhere), that code's: its records then agree with clean ones of the same code."""
    code, mine = str(p.get("code")), p.get("code_fingerprint")
    if "+" in code and mine is not None:
        base = code.split("+", 1)[0]
        if mine == fingerprint_at(base):
            code = base
        elif mine == code_fingerprint():
            return agent_fingerprint_at(None, agent)
    return agent_fingerprint_at(code, agent)


@functools.cache
def _module_fingerprint_at(code: str | None, module: str | None) -> str | None:
    sources = _sources_today() if code is None else _sources_at(code)
    return None if sources is None else scoped_fingerprint(sources, module)


@functools.cache
def _blob(blob: str) -> bytes:
    return _git("cat-file", "blob", blob, text=False)


def resolve(rec: dict) -> dict:
    """The record's provenance, a reconstructed one filled in from git, and the code's
    fingerprint from its commit where the record has none."""
    p = rec.get("provenance") or {}
    if p and "code_fingerprint" not in p:
        p = {**p, "code_fingerprint": fingerprint_at(str(p.get("code")))}
    if p and "agent" in rec:
        p = {**p, "agent_fingerprint": _agent_fingerprint_of(p, rec["agent"])}
    if p.get("reconstructed") != "git":
        return p
    commit = p["code"]
    try:
        weights = agent_weights_today(rec["agent"], rec["task"])
        sensor, task = rec.get("sensor", "ideal"), rec["task"]
        files = _hole_files().get(rec.get("object", ""), ())
        return {
            **p,
            "weights": None if weights is None else {f: _at(commit, f) for f in weights},
            "sensor": {"name": sensor, "file": f"sensors/{sensor}.yaml"}
            | {"sha256": _at(commit, f"sensors/{sensor}.yaml")},
            "task": {"name": task, "file": f"tasks/{task}.yaml"}
            | {"sha256": _at(commit, f"tasks/{task}.yaml")},
            "object": {"name": rec.get("object"), "files": {f: _at(commit, f) for f in files}},
        }
    except (OSError, subprocess.CalledProcessError):
        return {**p, "weights": None, "unresolved": "not in a git checkout with that commit"}


def signature(p: dict) -> tuple:
    """What must agree between the records of one cell, from a resolved provenance (the
    object's files may differ: a cell averages over objects)."""
    return (
        p.get("agent_fingerprint") or p.get("code_fingerprint") or p.get("code"),
        json.dumps(p.get("agent_code"), sort_keys=True),
        json.dumps(p.get("weights"), sort_keys=True),
        (p.get("sensor") or {}).get("sha256"),
        (p.get("task") or {}).get("sha256"),
    )


def _today(file: str) -> str | None:
    """sha256 of a recorded file as it is today (None: gone)."""
    path = Path(file) if Path(file).is_absolute() else resources.bundled_file(file)
    if not path.is_file() and not Path(file).is_absolute():
        path = PROJECT_ROOT / file  # a file of the checkout outside the bundle
    return sha256(path) if path.is_file() else None


@functools.cache
def agent_weights_today(agent: str, task: str, mount: str | None = None) -> dict[str, str] | None:
    """{file: sha256} the agent loads today for the task with its camera on the mount named
    `mount` (an agent may load weights trained for a mount; None: the default), None: it
    cannot be built."""
    from cfvs_maniskill import TASKS
    from cfvs_maniskill.policies.interface import TaskSpec
    from cfvs_maniskill.policies.registry import PRIVILEGED, resolve_agent
    from cfvs_maniskill.provenance import track_weights
    from cfvs_maniskill.robots.mounts import DEFAULT_MOUNT, MOUNTS

    if agent in PRIVILEGED:
        return {}  # the oracle loads nothing
    try:
        factory = resolve_agent(agent)
        with track_weights() as loaded:
            # a bracket of one's own is known here by its name, all weights_for reads
            on = MOUNTS.get(mount or DEFAULT_MOUNT) or replace(MOUNTS[DEFAULT_MOUNT], name=mount)
            factory(TaskSpec.of(TASKS[task], on))
    except Exception:  # removed from the registry, no weights for the task, ...
        return None
    return loaded


def code_current(rec: dict, p: dict) -> bool:
    """Whether the episode code the record's agent can run (`agent_fingerprint`, from the
    record's commit) is today's; a record of uncommitted code compares all of it."""
    if p.get("agent_fingerprint") is not None:
        return p["agent_fingerprint"] == agent_fingerprint_at(None, rec["agent"])
    return p.get("code_fingerprint") is not None and p["code_fingerprint"] == code_fingerprint()


def code_change(p: dict) -> str:
    if p.get("code_fingerprint") is None:
        return f"code {p.get('code')} unknown (not a commit of this checkout)"
    return f"episode code changed since {p.get('code')}"


def stale_reasons(rec: dict, p: dict) -> list[str]:
    """Why a record, of resolved provenance `p`, is not what today's code and files would
    give (empty: current)."""
    if not p:
        return ["no provenance"]
    out = [] if code_current(rec, p) else [code_change(p)]
    for kind in ("sensor", "task"):
        entry = p.get(kind) or {}
        if entry.get("file") and _today(entry["file"]) != entry.get("sha256"):
            out.append(f"{kind} file {entry['file']} changed since")
    for file, sha in ((p.get("object") or {}).get("files") or {}).items():
        if _today(file) != sha:
            out.append(f"hole file {file} changed since")
    for file, sha in (p.get("agent_code") or {}).items():
        if _today(file) != sha:
            out.append(f"agent code {file} changed since")
    if p.get("weights") is None:
        out.append("weights unknown")
    else:
        today = agent_weights_today(rec["agent"], rec["task"], rec.get("mount"))
        if today is None:
            out.append(f"agent {rec['agent']} cannot be built today")
        elif today != p["weights"]:
            changed = sorted(set(today.items()) ^ set(p["weights"].items()))
            out.append("other weights today: " + ", ".join(sorted({f for f, _ in changed})))
    return out


def cell_status(recs: list[dict]) -> tuple[str, list[str]]:
    """("ok" | "mixed" | "stale" | "crashed", reasons) of one table cell's records."""
    reasons: Counter = Counter()
    if any(r.get("crashed") for r in recs):
        reasons["crashed jobs (eval --retry-crashed)"] += 1
    resolved = [resolve(r) for r in recs]
    sigs = {signature(p) for p in resolved}
    if len(sigs) > 1:
        codes = sorted({str(s[0]) for s in sigs})
        reasons[f"mixed: {len(sigs)} provenances (code {', '.join(codes)})"] += 1
    for r, p in zip(recs, resolved, strict=True):
        for why in stale_reasons(r, p):
            reasons[why] += 1
    if not reasons:
        return "ok", []
    kind = (
        "crashed"
        if any(k.startswith("crashed") for k in reasons)
        else "mixed"
        if any(k.startswith("mixed") for k in reasons)
        else "stale"
    )
    return kind, [f"{k} ({n} records)" if n > 1 else k for k, n in reasons.items()]


def code_versions(recs: list[dict]) -> str:
    """'abc123 (180), def456 (20)': the code versions of some records, most first."""
    c = Counter(str((r.get("provenance") or {}).get("code")) for r in recs)
    return ", ".join(f"{k} ({n})" for k, n in c.most_common())
