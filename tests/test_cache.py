"""The hole cache under concurrency: any number of processes building or loading the same
cache key at once publish atomically, never delete a complete entry and never read a
partial one."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import manifold3d as mf
import numpy as np
import pytest
import trimesh

from tests.conftest import ROOT

PROCESSES = 4

# One process: build every spec in ASSETS (geometry + the OBJ files SAPIEN loads), load the
# OBJ files back, and print a digest of all of it. All processes start at the same instant.
BUILD = """
import hashlib, json, sys, time
from pathlib import Path
import numpy as np, trimesh
from cfvs_maniskill.objects.build import build_geometry
from cfvs_maniskill.objects.library import load_library
lib = load_library([sys.argv[1]], include_default=False)
assert not lib.errors, lib.errors
while time.time() < float(sys.argv[2]):
    time.sleep(0.005)
out = {}
for name, spec in sorted(lib.specs.items()):
    g = build_geometry(spec, "square", 0.004, 0.045)
    visual, parts = g.mesh_files()
    h = hashlib.sha256(g.visual_vertices.tobytes() + g.visual_faces.tobytes())
    for v, f in g.collision_parts:
        h.update(np.asarray(v).tobytes() + np.asarray(f).tobytes())
    for p in [visual, *parts]:
        assert len(trimesh.load(p, force="mesh").faces) > 0, p
        h.update(p.read_bytes())
    out[name] = h.hexdigest()
print(json.dumps(out))
"""


def _new_shapes(folder: Path) -> Path:
    """Shapes no cache has seen: an L-shaped mesh body (convex decomposition) and a box."""
    folder.mkdir(parents=True)
    a = mf.Manifold.cube([0.16, 0.09, 0.07])
    b = mf.Manifold.cube([0.07, 0.16, 0.07])
    m = (a + b).to_mesh()
    trimesh.Trimesh(np.asarray(m.vert_properties)[:, :3], np.asarray(m.tri_verts)).export(
        folder / "ell.stl"
    )
    (folder / "ell.yaml").write_text(
        "name: cache_ell\nhole: square\nbody:\n  mesh: {file: ell.stl}\nhole_at: [-0.04, -0.035]\n"
    )
    (folder / "box.yaml").write_text(
        "name: cache_box\nbody:\n  box: {size: [0.137, 0.151, 0.071]}\nhole_at: [0.01, 0.0]\n"
    )
    return folder


def test_processes_building_the_same_new_shapes_at_once_agree(tmp_path):
    assets = _new_shapes(tmp_path / "assets")
    env = {**os.environ, "CFVS_CACHE": str(tmp_path / "cache")}
    start = time.time() + 8  # after every process has imported the package
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", BUILD, str(assets), str(start)],
            cwd=ROOT,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        for _ in range(PROCESSES)
    ]
    results = [p.communicate(timeout=600) for p in procs]
    for p, (_out, err) in zip(procs, results, strict=True):
        assert p.returncode == 0, err[-3000:]
    digests = [json.loads(out.strip().splitlines()[-1]) for out, _ in results]
    assert digests[0].keys() == {"cache_ell", "cache_box"}
    assert all(d == digests[0] for d in digests), digests
    holes = tmp_path / "cache" / "holes"
    assert not [p for p in holes.iterdir() if p.name.startswith(".")], "temporary files left"


@pytest.mark.slow
def test_first_evaluation_with_two_workers_on_an_empty_cache(tmp_path):
    assets = _new_shapes(tmp_path / "assets")
    env_cache = tmp_path / "cache"
    r = subprocess.run(
        [sys.executable, "-m", "cfvs_maniskill.eval", "--tasks", "PegInsert6DoF",
         "--agents", "oracle", "--objects", "cache_ell", "cache_box", "--assets", str(assets),
         "--init-errors", "small", "--episodes-per-object", "1", "--workers", "2",
         "--out", str(tmp_path / "out")],
        cwd=ROOT, env={**os.environ, "CFVS_CACHE": str(env_cache)},
        capture_output=True, text=True, timeout=900,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr[-3000:]
    lines = (tmp_path / "out" / "episodes.jsonl").read_text().splitlines()
    assert sorted(json.loads(x)["object"] for x in lines) == ["cache_box", "cache_ell"]
    # One entry per shape, each complete.
    entries = [p for p in (env_cache / "holes").iterdir() if p.is_dir()]
    assert len(entries) == 2 and all((p / "visual.obj").is_file() for p in entries)


def test_a_late_builder_never_replaces_a_published_entry(tmp_path, monkeypatch):
    """The race without timing luck: a process that looked before another one published
    the entry (it saw no files) builds and publishes too. It must use the published entry
    and leave it in place (same files, same inodes), not delete and replace it."""
    from cfvs_maniskill.objects import build
    from cfvs_maniskill.objects.spec import load_spec

    monkeypatch.setenv("CFVS_CACHE", str(tmp_path / "cache"))
    spec = load_spec(_new_shapes(tmp_path / "assets") / "box.yaml")
    g = build.build_geometry(spec, "square")
    visual, parts = g.mesh_files()
    files = [build.cache_dir() / f"{g.cache_key}.npz", visual, *parts]
    inodes = [p.stat().st_ino for p in files]

    stale = {"view": True}  # until it publishes, the late process sees no cache files
    real_is_file, real_rename, real_link = Path.is_file, os.rename, os.link

    def is_file(self):
        if stale["view"] and self.suffix in (".npz", ".obj"):
            return False
        return real_is_file(self)

    def publishing(real):
        def call(*args, **kwargs):
            stale["view"] = False
            return real(*args, **kwargs)

        return call

    monkeypatch.setattr(Path, "is_file", is_file)
    monkeypatch.setattr(os, "rename", publishing(real_rename))
    monkeypatch.setattr(os, "link", publishing(real_link))
    late = build.build_geometry(spec, "square")
    assert [p.stat().st_ino for p in files] == inodes
    stale["view"] = True
    assert late.mesh_files() == (visual, parts)
    assert [p.stat().st_ino for p in files] == inodes
