"""Helpers for the scripts that write mesh bodies for hole files (the held-out sets'
`make_meshes.py`): constructive solid geometry with manifold booleans, and writing the
bodies beside the script."""

from __future__ import annotations

from pathlib import Path

import trimesh


def solid(keep: list[trimesh.Trimesh], cut: tuple | list = ()) -> trimesh.Trimesh:
    """The union of `keep` less the union of `cut` (manifold booleans: watertight out)."""
    m = trimesh.boolean.union(list(keep), engine="manifold") if len(keep) > 1 else keep[0]
    return trimesh.boolean.difference([m, *cut], engine="manifold") if cut else m


def write_bodies(meshes: dict[str, trimesh.Trimesh], folder: Path) -> None:
    """Write each body as `<folder>/<name>.stl` (metres), after checking it is watertight
    (the hole library cuts holes into it), and print its bounds."""
    for name, mesh in meshes.items():
        if not mesh.is_watertight:
            raise ValueError(f"{name}: the mesh body is not watertight")
        mesh.export(Path(folder) / f"{name}.stl")
        print(name, mesh.bounds.round(3).tolist())
