"""The package layout keeps its promises: the data pipeline and the agents share what
reads the camera through `perception/`, and neither imports the other."""

from __future__ import annotations

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parent.parent / "cfvs_maniskill"


def _imports(folder: str) -> dict[str, set[str]]:
    out = {}
    for f in sorted((PKG / folder).glob("*.py")):
        names = set()
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                names.add(node.module)
            elif isinstance(node, ast.Import):
                names.update(a.name for a in node.names)
        out[f.name] = names
    return out


def test_data_and_agents_do_not_import_each_other():
    for folder, other in (("data", "agents"), ("agents", "data")):
        bad = {
            f: sorted(n for n in names if n.startswith(f"cfvs_maniskill.{other}"))
            for f, names in _imports(folder).items()
        }
        assert not any(bad.values()), f"{folder}/ imports {other}/: {bad}"
    for f, names in _imports("perception").items():
        assert not any(
            n.startswith(("cfvs_maniskill.data", "cfvs_maniskill.agents")) for n in names
        ), f
