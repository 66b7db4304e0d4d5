"""The package layout keeps its promises: the layers of docs/architecture.md, in the source
and at run time, and policies that share what reads the camera through `perception/`."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parent.parent / "cfvs_maniskill"


def _module_imports(f: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(f.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
        elif isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
    return names


def _imports(folder: str) -> dict[str, set[str]]:
    return {f.name: _module_imports(f) for f in sorted((PKG / folder).glob("*.py"))}


POLICY_TOOLS = ("collect", "train", "diagnose")
"""A policy folder's modules that make its data and weights, not its decisions."""


def test_policies_data_and_control_do_not_import_each_other():
    """Policies decide, the controller carries decisions out, data is made as policies see:
    a policy's deciding code reaches into neither, the controller into no policy, and a
    policy's data and training reach the data pipeline only."""
    deciding = {
        f"{f.parent.name}/{f.name}": names
        for f in sorted((PKG / "policies").rglob("*.py"))
        if f.stem not in POLICY_TOOLS
        for names in [_module_imports(f)]
    }
    for where, names in deciding.items():
        bad = [n for n in names if n.startswith(("cfvs_maniskill.data", "cfvs_maniskill.control"))]
        assert not bad, f"policies/{where} imports {bad}"
    for f, names in _imports("control").items():
        assert not any(n.startswith("cfvs_maniskill.policies") for n in names), f
    for f, names in _imports("perception").items():
        assert not any(
            n.startswith(("cfvs_maniskill.data", "cfvs_maniskill.policies")) for n in names
        ), f


LAYERS = {
    "constants": 0, "errors": 0, "geometry": 0, "task_dof": 0, "validation": 0,
    "resources": 0, "provenance": 0, "rendering.device": 0, "rendering": 0, "rendering.views": 1,
    "robots": 1, "objects": 1, "sensing": 1,
    "envs": 2, "": 2,
    "perception": 3, "nets": 3,
    "policies": 4, "control": 4,
    "episode": 5, "session": 5, "run": 5, "eval": 5, "report": 5, "data": 5,
    "assets": 5, "tool": 5, "cli": 5, "stats": 5, "rendering.film": 5,
}  # fmt: skip
"""docs/architecture.md's layers: a module (or its package) -> its layer; "" is the
package root (it registers the envs)."""


def _layer(module: str) -> int:
    name = module.removeprefix("cfvs_maniskill").removeprefix(".")
    if name.startswith("policies.") and name.rsplit(".", 1)[-1] in POLICY_TOOLS:
        return 5  # a policy's data collection, training and diagnosis are tools
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


HEAVY = ("sapien", "mani_skill", "torch", "open3d")
"""The simulator, the renderer and the learning stack: loaded when an env or a network is
made, never by importing the package or its lowest layer."""
WITHOUT_SIMULATOR = ("cfvs_maniskill.report.load", "cfvs_maniskill.report.tables",
                     "cfvs_maniskill.report.paper", "cfvs_maniskill.eval.results",
                     "cfvs_maniskill.eval.summary", "cfvs_maniskill.envs.lookup")  # fmt: skip
"""Reading records and tasks and writing the report's tables: no simulator, no renderer."""


def _modules() -> list[str]:
    out = []
    for f in sorted(PKG.rglob("*.py")):
        if "bundled" in f.parts or f.name == "__main__.py":  # __main__ runs its CLI
            continue
        rel = f.relative_to(PKG).with_suffix("")
        out.append(".".join(("cfvs_maniskill", *rel.parts)).removesuffix(".__init__"))
    return out


def _loaded_by(modules: list[str]) -> set[str]:
    """sys.modules of a fresh interpreter after importing `modules`."""
    code = f"import importlib, json, sys\nfor m in {modules!r}:\n    importlib.import_module(m)\n"
    code += "print(json.dumps(sorted(sys.modules)))"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    return set(json.loads(r.stdout.strip().splitlines()[-1]))


def test_importing_the_package_loads_nothing_heavy():
    loaded = _loaded_by(["cfvs_maniskill"])
    assert not {m.split(".")[0] for m in loaded} & set(HEAVY)
    import gymnasium as gym

    import cfvs_maniskill

    assert {t.env_id for t in cfvs_maniskill.TASKS.values()} <= set(gym.registry)


@pytest.mark.parametrize("layer", sorted(set(LAYERS.values())))
def test_importing_a_layer_loads_nothing_above_it(layer):
    """At run time: a fresh interpreter importing every module of `layer` and below loads no
    module of a higher layer (beyond the light registration the package root always runs)."""
    root = _loaded_by(["cfvs_maniskill"])
    loaded = _loaded_by([m for m in _modules() if _layer(m) <= layer])
    above = sorted(m for m in loaded - root if m.startswith("cfvs_maniskill") and _layer(m) > layer)
    assert not above, f"importing layer {layer} loads {above}"
    if layer == 0:
        assert not {m.split(".")[0] for m in loaded} & set(HEAVY)


def test_records_and_tables_need_no_simulator():
    loaded = _loaded_by(list(WITHOUT_SIMULATOR))
    assert not {m.split(".")[0] for m in loaded} & set(HEAVY)
