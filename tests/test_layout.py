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


def test_data_agents_and_control_do_not_import_each_other():
    """Agents decide, the controller carries decisions out, data is made as agents see:
    none of the three reaches into another."""
    pairs = [("data", "agents"), ("agents", "data"), ("agents", "control"), ("control", "agents")]
    for folder, other in pairs:
        bad = {
            f: sorted(n for n in names if n.startswith(f"cfvs_maniskill.{other}"))
            for f, names in _imports(folder).items()
        }
        assert not any(bad.values()), f"{folder}/ imports {other}/: {bad}"
    for f, names in _imports("perception").items():
        assert not any(
            n.startswith(("cfvs_maniskill.data", "cfvs_maniskill.agents")) for n in names
        ), f


LAYERS = {
    "constants": 0, "errors": 0, "geometry": 0, "task_dof": 0, "validation": 0,
    "resources": 0, "provenance": 0, "rendering.device": 0, "rendering": 0, "rendering.views": 1,
    "robots": 1, "objects": 1, "sensing": 1,
    "envs": 2, "": 2,
    "perception": 3, "nets": 3,
    "agents": 4, "control": 4,
    "episode": 5, "session": 5, "run": 5, "eval": 5, "report": 5, "data": 5, "train": 5, "train_kovis": 5,
    "assets": 5, "tool": 5, "diagnose_kovis": 5, "cli": 5, "stats": 5, "rendering.film": 5,
}  # fmt: skip
"""docs/architecture.md's layers: a module (or its package) -> its layer; "" is the
package root (it registers the envs)."""


def _layer(module: str) -> int:
    name = module.removeprefix("cfvs_maniskill").removeprefix(".")
    while name not in LAYERS:
        assert "." in name, f"cfvs_maniskill.{name} has no layer in LAYERS"
        name = name.rsplit(".", 1)[0]
    return LAYERS[name]


def test_no_module_imports_from_a_higher_layer():
    bad = []
    for f in sorted(PKG.rglob("*.py")):
        if "bundled" in f.parts:
            continue
        rel = f.relative_to(PKG).with_suffix("")
        module = ".".join(("cfvs_maniskill", *rel.parts)).removesuffix(".__init__")
        for node in ast.walk(ast.parse(f.read_text())):
            targets = []
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith(
                "cfvs_maniskill"
            ):
                if node.module == "cfvs_maniskill":  # `from cfvs_maniskill import x`
                    targets = [f"cfvs_maniskill.{a.name}" for a in node.names]
                    targets = [t if _has_layer(t) else "cfvs_maniskill" for t in targets]
                else:
                    targets = [node.module]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names if a.name.startswith("cfvs_maniskill")]
            bad += [
                f"{module} ({_layer(module)}) imports {t} ({_layer(t)})"
                for t in targets
                if _layer(t) > _layer(module)
            ]
    assert not bad, "imports from a higher layer (docs/architecture.md):\n" + "\n".join(bad)


def _has_layer(module: str) -> bool:
    name = module.removeprefix("cfvs_maniskill.")
    return name.split(".")[0] in LAYERS
