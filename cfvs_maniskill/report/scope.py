"""Which of the episode code can decide an agent's episodes: the modules they import.

A record is stale when the code its episode ran has changed. That code is what an episode
imports: the package and the modules that run an episode (`ROOTS`), the env they make, and
the agent's own module with all it imports, followed through every `import` statement in
the package, inside functions too. The registry imports each policy folder by name to list
its agents, so those folders' `__init__` modules count for every agent, but only what they
import at module level: an import inside an entry's factory runs only when that agent is
built, and is followed from that agent's own module instead. So a change to CFVS's fine
stage leaves KOVIS's records current, while a change to the env, the sensor models, the
controller or anything an agent shares with CFVS does not.

An agent defined outside the package (`module:Class`) may import any of it: its records
are judged on the whole episode code (the scope is None)."""

from __future__ import annotations

import ast
import functools
import hashlib
from collections.abc import Iterator

from cfvs_maniskill.provenance import fingerprint, is_episode_code

PACKAGE = "cfvs_maniskill"
ROOTS = ("__init__.py", "session.py", "episode.py", "eval/worker.py")
"""The modules that make an env and run an episode (run.py and eval's orchestration import
them)."""
POLICIES = "policies/"


def _walk(tree: ast.AST, top_level: bool) -> Iterator[ast.AST]:
    """The nodes of `tree`; with `top_level`, not those inside a function's body."""
    todo = [tree]
    while todo:
        node = todo.pop()
        yield node
        for child in ast.iter_child_nodes(node):
            if top_level and isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                continue
            todo.append(child)


def _module_paths(dotted: str, sources: dict[str, bytes]) -> list[str]:
    """The package's files for module `dotted` (absolute) and its parent packages."""
    parts = dotted.split(".")
    if parts[0] != PACKAGE:
        return []
    out = []
    for k in range(1, len(parts) + 1):
        stem = "/".join(parts[1:k])
        for path in (f"{stem}/__init__.py" if stem else "__init__.py", f"{stem}.py"):
            if path in sources:
                out.append(path)
    return out


@functools.cache
def _imports(path: str, source: bytes, top_level: bool) -> tuple[str, ...]:
    """The dotted names module `path` imports (`top_level`: outside functions), each with
    `from X import Y`'s X.Y too (Y may be a module)."""
    package = [PACKAGE, *path.split("/")[:-1]]  # a module's package; an __init__'s own
    out = []
    for node in _walk(ast.parse(source), top_level):
        if isinstance(node, ast.Import):
            out.extend(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            dotted = ".".join([*base, *([node.module] if node.module else [])])
            out.extend([dotted, *(f"{dotted}.{alias.name}" for alias in node.names)])
    return tuple(out)


def imported(path: str, sources: dict[str, bytes], top_level: bool = False) -> set[str]:
    """The package's files that module `path` imports (`top_level`: outside functions)."""
    names = _imports(path, sources[path], top_level)
    return {f for name in names for f in _module_paths(name, sources)}


def agent_scope(sources: dict[str, bytes], agent_module: str | None) -> set[str] | None:
    """The files (paths in the package) an episode of the agent whose class lives in module
    `agent_module` (dotted) can run; None for a module outside the package."""
    if agent_module is None or not agent_module.startswith(f"{PACKAGE}."):
        return None
    registry_reads = {  # policies/<folder>/__init__.py
        p
        for p in sources
        if p.startswith(POLICIES) and p.endswith("/__init__.py") and p.count("/") == 2
    }
    seen: set[str] = set()
    todo = [*ROOTS, *_module_paths(agent_module, sources)]
    for init in registry_reads:
        seen.add(init)
        todo.extend(imported(init, sources, top_level=True))
    while todo:
        path = todo.pop()
        if path in seen or path not in sources:
            continue
        seen.add(path)
        todo.extend(imported(path, sources))
    return seen


@functools.cache
def _module_fingerprint(path: str, source: bytes) -> str:
    return fingerprint([(path, source)])


def scoped_fingerprint(sources: dict[str, bytes], agent_module: str | None) -> str:
    """A hash of the fingerprints (provenance.fingerprint, module by module: each parsed
    once however many agents and commits share it) of the episode code in the agent's
    scope; of all of it for an agent outside the package."""
    scope = agent_scope(sources, agent_module)
    h = hashlib.sha256()
    for path in sorted(p for p in sources if is_episode_code(p) and (scope is None or p in scope)):
        h.update(f"{path}\0{_module_fingerprint(path, sources[path])}\0".encode())
    return h.hexdigest()[:16]
