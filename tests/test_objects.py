"""Default hole objects: geometry, the open hole, the peg fit and the disk cache."""

from __future__ import annotations

import manifold3d as mf
import numpy as np
import pytest

from cfvs_maniskill.constants import (
    DEFAULT_CLEARANCE,
    DEFAULT_HOLE_DEPTH,
    PEG_LENGTH,
    hole_half_extent,
    peg_half_extent,
)
from cfvs_maniskill.data.shapes import box_at
from cfvs_maniskill.objects.build import build_geometry, cache_dir, hole_solid
from cfvs_maniskill.objects.library import load_library

LIB = load_library()
CASES = [(n, p) for n, s in sorted(LIB.specs.items()) for p in s.hole]


def _solid(v, f) -> mf.Manifold:
    return mf.Manifold(
        mf.Mesh(vert_properties=np.asarray(v, np.float32), tri_verts=np.asarray(f, np.uint32))
    )


def test_default_library_mirrors_the_paper():
    assert not LIB.errors
    train = [s for s in LIB.specs.values() if s.split == "train"]
    test = [s for s in LIB.specs.values() if s.split == "test"]
    assert len(train) == 4 and all(s.body_kind == "box" for s in train)
    kinds = sorted(s.body_kind for s in test)
    assert kinds == ["box", "box", "cylinder", "prism"]
    assert next(s for s in test if s.body_kind == "prism").body["sides"] == 5


@pytest.mark.parametrize(("name", "profile"), CASES)
def test_hole_is_cut_open_and_fits_the_peg(name, profile):
    g = build_geometry(LIB.specs[name], profile)
    mesh = g.visual_trimesh()
    assert mesh.is_watertight and mesh.volume > 0
    x, y, z_top = g.hole_frame
    half = hole_half_extent(profile, DEFAULT_CLEARANCE)
    depth = DEFAULT_HOLE_DEPTH

    # The hole is open: its volume shrunk by 1 mm (and the space above it) touches no
    # collision part.
    probe = hole_solid(profile, half - 0.001, z_top - depth + 0.001, z_top + 0.1, (x, y))
    for v, _ in g.collision_parts:
        hull = mf.Manifold.hull_points(np.asarray(v, np.float32))
        assert (hull ^ probe).volume() < 1e-9, f"{name}/{profile}: a collision part fills the hole"

    body = _solid(g.visual_vertices, g.visual_faces)
    peg = peg_half_extent(profile)
    # The peg fits down to (almost) the bottom...
    assert (
        body ^ hole_solid(profile, peg, z_top - depth + 0.0005, z_top + PEG_LENGTH, (x, y))
    ).volume() < 1e-9
    # ...but the floor stops it, and the walls stop a peg off the axis by more than the play.
    assert (body ^ hole_solid(profile, peg, z_top - depth - 0.002, z_top, (x, y))).volume() > 1e-7
    off = (x + DEFAULT_CLEARANCE / 2 + 0.001, y)
    assert (body ^ hole_solid(profile, peg, z_top - depth / 2, z_top, off)).volume() > 1e-7
    # Collision parts cover the body (no missing walls): their hulls hold its volume.
    hull_vol = sum(
        mf.Manifold.hull_points(np.asarray(v, np.float32)).volume() for v, _ in g.collision_parts
    )
    assert hull_vol == pytest.approx(mesh.volume, rel=0.02)


def test_cached_build_is_reused_and_identical():
    spec = LIB.specs["cylinder"]
    a = build_geometry(spec, "round")
    assert (cache_dir() / f"{a.cache_key}.npz").is_file()
    b = build_geometry(spec, "round")
    assert a.cache_key == b.cache_key
    assert np.array_equal(a.visual_vertices, b.visual_vertices)
    assert len(a.collision_parts) == len(b.collision_parts)
    c = build_geometry(spec, "round", clearance=0.001)  # another clearance, another entry
    assert c.cache_key != a.cache_key
    assert c.hole_half_extent == pytest.approx(0.0235)


def test_mesh_body_goes_through_coacd(tmp_path):
    import trimesh

    # An L-shaped bracket in millimetres: concave, so it needs a real decomposition.
    boxes = [box_at([150, 120, 70], [0, 0, 35]), box_at([40, 120, 60], [95, 0, 30])]
    trimesh.boolean.union(boxes, engine="manifold").export(tmp_path / "bracket.stl")
    (tmp_path / "bracket.yaml").write_text(
        "split: test\nbody:\n  mesh: {file: bracket.stl, scale: 0.001}\nhole_at: [-0.02, 0.0]\n"
    )
    lib = load_library([tmp_path], include_default=False)
    assert not lib.errors
    g = build_geometry(lib.specs["bracket"], "square")
    assert g.visual_trimesh().is_watertight
    assert g.hole_frame[2] == pytest.approx(0.07, abs=1e-4)
    assert len(g.collision_parts) >= 5


@pytest.mark.slow
def test_huge_mesh_is_simplified_with_a_warning_and_cached(tmp_path, caplog, monkeypatch):
    import logging
    import time

    import trimesh

    from cfvs_maniskill.objects.build import MAX_BODY_FACES

    monkeypatch.setenv("CFVS_CACHE", str(tmp_path / "cache"))  # a cold cache every run
    # A scanned-part-sized mesh: a 150 x 120 x 70 mm block with ~786 000 triangles.
    block = trimesh.creation.box([0.15, 0.12, 0.07])
    for _ in range(8):
        block = block.subdivide()
    assert len(block.faces) > 700_000
    block.export(tmp_path / "scan.stl")
    (tmp_path / "scan.yaml").write_text("split: test\nbody:\n  mesh: {file: scan.stl}\n")
    lib = load_library([tmp_path], include_default=False)
    assert not lib.errors
    with caplog.at_level(logging.WARNING):
        g = build_geometry(lib.specs["scan"], "round")
    said = " ".join(r.getMessage() for r in caplog.records)
    assert "scan.yaml" in said and "body.mesh.file" in said and f"{len(block.faces)}" in said
    assert len(g.visual_faces) < MAX_BODY_FACES
    assert g.visual_trimesh().is_watertight
    assert g.hole_frame[2] == pytest.approx(0.07, abs=1e-4)
    caplog.clear()
    t = time.perf_counter()
    again = build_geometry(lib.specs["scan"], "round")  # from the cache: no second pass
    assert time.perf_counter() - t < 5 and not caplog.records
    assert np.array_equal(again.visual_faces, g.visual_faces)


@pytest.mark.parametrize(("profile", "clearance"), [("square", 0.0005), ("round", 0.001)])
def test_a_concave_bodys_hole_wall_has_no_seam_and_no_part_in_the_clearance(
    tmp_path, profile, clearance
):
    """A boss on a plate: CoACD used to cut the hole wall where the boss meets the plate,
    and a peg sliding down a 0.25 mm gap caught on the lower part's edge there. The wall
    must be one convex part per wedge from the floor to the opening, and no part may
    reach into the hole beyond a round wall's facet sagitta (clearance / 8, probed at / 6:
    the probe is a polygon too)."""
    import trimesh

    plate = trimesh.creation.box([0.20, 0.16, 0.03])
    plate.apply_translation([0, 0, 0.015])
    boss = trimesh.creation.cylinder(0.045, 0.032, sections=64)
    boss.apply_translation([0.02, 0, 0.044])
    trimesh.boolean.union([plate, boss], engine="manifold").export(tmp_path / "boss.stl")
    (tmp_path / "boss.yaml").write_text(
        "split: test\nbody:\n  mesh: {file: boss.stl}\n"
        "hole_frame: {origin: [0.02, 0.0, 0.06], axis: [0.0, 0.0, 1.0]}\n"
    )
    lib = load_library([tmp_path], include_default=False)
    assert not lib.errors
    g = build_geometry(lib.specs["boss"], profile, clearance=clearance, use_cache=False)
    x, y, z_top = g.hole_frame
    half = g.hole_half_extent
    bottom = z_top - DEFAULT_HOLE_DEPTH
    heights = set()
    for v, _ in g.collision_parts:
        d = v[:, :2] - np.array([x, y])
        r = np.abs(d).max(axis=1) if profile == "square" else np.linalg.norm(d, axis=1)
        on_wall = v[np.abs(r - half) < 5e-5]
        heights |= {round(float(z) - bottom, 4) for z in on_wall[:, 2]}
    assert heights, "no part lines the hole wall"
    inner = sorted(h for h in heights if 0.0005 < h < DEFAULT_HOLE_DEPTH - 0.0005)
    assert not inner, f"the wall has seams at {inner} m above the hole's floor"
    probe = hole_solid(profile, half - clearance / 6, bottom + 1e-4, z_top + 0.05, (x, y))
    for v, _ in g.collision_parts:
        hull = mf.Manifold.hull_points(np.asarray(v, np.float32))
        assert (hull ^ probe).volume() < 1e-12
    hull_vol = sum(
        mf.Manifold.hull_points(np.asarray(v, np.float32)).volume() for v, _ in g.collision_parts
    )
    assert hull_vol == pytest.approx(g.visual_trimesh().volume, rel=0.02)


def test_mesh_body_helpers_cut_a_watertight_body_and_refuse_an_open_one(tmp_path):
    """The held-out sets' `make_meshes.py` build bodies with these: a plate less a slot
    stays watertight and is written beside the script; an open mesh is refused by name."""
    import trimesh
    from trimesh.creation import box

    from cfvs_maniskill.objects.meshes import solid, write_bodies

    plate = solid([box([0.2, 0.2, 0.05])], [box([0.22, 0.006, 0.01])])
    assert plate.is_watertight and plate.volume < 0.2 * 0.2 * 0.05
    write_bodies({"slotted": plate}, tmp_path)
    assert trimesh.load(tmp_path / "slotted.stl").is_watertight
    open_mesh = trimesh.Trimesh(plate.vertices, plate.faces[:-2])
    with pytest.raises(ValueError, match="open: the mesh body is not watertight"):
        write_bodies({"open": open_mesh}, tmp_path)
