"""Holes on any planar face (`hole_frame`): real CAD parts whose top is a boss or a curved
surface, primitives with the hole in a side, and every way the frame can be wrong."""

from __future__ import annotations

import manifold3d as mf
import numpy as np
import pytest
import trimesh

from cfvs_maniskill.constants import DEFAULT_CLEARANCE, DEFAULT_HOLE_DEPTH, PEG_LENGTH, PROJECT_ROOT
from cfvs_maniskill.data.shapes import box_at
from cfvs_maniskill.objects.build import (
    build_geometry,
    check_room,
    hole_solid,
    oriented_body,
)
from cfvs_maniskill.objects.library import load_library
from cfvs_maniskill.objects.spec import HoleSpecError, load_spec

CAD = PROJECT_ROOT / "assets" / "cad_parts"


def _write(tmp_path, text: str, name: str = "part.yaml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def _boss_part(folder):
    """A 200 x 140 x 60 mm base with a 40 mm boss on top at one end (in millimetres):
    the body's global top is the boss, too small for the hole."""
    boxes = [box_at([200, 140, 60], [0, 0, 30]), box_at([50, 50, 40], [70, 0, 80])]
    trimesh.boolean.union(boxes, engine="manifold").export(folder / "boss.stl")


def test_bundled_cad_parts_validate_outside_the_default_library():
    lib = load_library([CAD], include_default=False)
    assert not lib.errors
    assert sorted(lib.specs) == ["cad_angle_block", "cad_fandisk", "cad_featuretype"]
    assert not set(lib.specs) & set(load_library().specs)  # the default split is unchanged
    assert (CAD / "LICENSE.md").is_file() and "MIT" in (CAD / "LICENSE.md").read_text()
    for spec in lib.specs.values():
        body, at, z = oriented_body(spec)
        origin = check_room(spec, body, "square", DEFAULT_CLEARANCE, DEFAULT_HOLE_DEPTH, at, z)
        lo, hi = np.asarray(body.bounding_box()).reshape(2, 3)
        assert 0.1 <= (hi - lo).max() <= 0.31, spec.name  # scaled to 10-30 cm
        assert abs(origin[2] - z) < 1e-3


def test_hole_on_a_lower_face_beside_a_boss(tmp_path):
    """The global top is a boss: hole_at fails, naming how much face is missing;
    hole_frame on the base's top face (file coordinates, mm) works."""
    _boss_part(tmp_path)
    mesh = "body:\n  mesh: {file: boss.stl, scale: 0.001}\n"
    with pytest.raises(HoleSpecError, match="mm missing") as e:
        build_geometry(load_spec(_write(tmp_path, mesh + "hole_at: [0.07, 0.0]\n")), "square")
    assert "'body.mesh.file'" in str(e.value)
    spec = load_spec(
        _write(tmp_path, mesh + "hole_frame: {origin: [-40, 0, 60], axis: [0, 0, 1]}\n")
    )
    g = build_geometry(spec, "square", use_cache=False)
    # The body frame is centred on the bounding box: x -40 mm -> -40 mm, opening at 60 mm.
    np.testing.assert_allclose(g.hole_frame, [-0.04, 0.0, 0.06], atol=1e-6)
    _assert_open_hole(g)


@pytest.mark.parametrize(
    ("origin", "axis"),
    [([0.065, 0.0, 0.035], [1, 0, 0]), ([0.0, -0.065, 0.035], [0, -1, 0])],
)
def test_hole_in_the_side_of_a_box(tmp_path, origin, axis):
    """Primitive bodies take hole_frame in the body frame: the box is turned on its side
    and the hole's axis is the side's normal."""
    text = f"body:\n  box: {{size: [0.13, 0.13, 0.07]}}\nhole_frame: {{origin: {origin}, axis: {axis}}}\n"
    g = build_geometry(load_spec(_write(tmp_path, text)), "square", use_cache=False)
    assert g.body_height == pytest.approx(0.13, abs=1e-6)  # 13 cm along the old side
    assert g.hole_frame[2] == pytest.approx(0.13, abs=1e-6)
    _assert_open_hole(g)


def _assert_open_hole(g):
    x, y, z = g.hole_frame
    half = g.hole_half_extent
    probe = hole_solid(g.profile, half - 0.001, z - g.depth + 0.001, z + PEG_LENGTH, (x, y))
    for v, _ in g.collision_parts:
        hull = mf.Manifold.hull_points(np.asarray(v, np.float32))
        assert (hull ^ probe).volume() < 1e-9
    body = mf.Manifold(
        mf.Mesh(
            vert_properties=np.asarray(g.visual_vertices, np.float32),
            tri_verts=np.asarray(g.visual_faces, np.uint32),
        )
    )
    floor = hole_solid(g.profile, half, z - g.depth - 0.002, z - g.depth - 0.0005, (x, y))
    assert (floor ^ body).volume() == pytest.approx(floor.volume(), rel=1e-3)  # a floor


@pytest.mark.parametrize(
    ("frame", "field", "words"),
    [
        # Fields the file gets wrong, refused when it is read:
        ("{origin: [-40, 0, 60]}", "hole_frame.axis", "missing"),
        ("{origin: [-40, 0, 60], axis: [0, 0, 0]}", "hole_frame.axis", "non-zero"),
        ("{origin: [-40, 0], axis: [0, 0, 1]}", "hole_frame.origin", "list of 3"),
        ("{origin: [-40, 0, 60], axis: [0, 0, 1], up: 1}", "hole_frame.up", "unknown"),
        ("[0, 0, 1]", "hole_frame", "mapping"),
        # Frames off the part, refused when the geometry is built:
        # 5 mm above the base's face: not on any face.
        ("{origin: [-40, 0, 65], axis: [0, 0, 1]}", "hole_frame.origin", "5.0 mm from"),
        # The base's face with the axis pointing into the part.
        ("{origin: [-40, 0, 60], axis: [0, 0, -1]}", "hole_frame.axis", "into the part"),
        # Beside the boss: the boss sits over the opening.
        ("{origin: [40, 0, 60], axis: [0, 0, 1]}", "hole_frame.origin", "over the opening"),
        # On the boss's top: 50 mm of face is too little for the 56 mm the hole needs.
        ("{origin: [70, 0, 100], axis: [0, 0, 1]}", "body.mesh.file", "mm missing"),
    ],
)
def test_a_bad_hole_frame_says_what_is_wrong(tmp_path, frame, field, words):
    """A wrong field or a frame off the part: the error names the file and the field."""
    _boss_part(tmp_path)
    p = _write(tmp_path, f"body:\n  mesh: {{file: boss.stl, scale: 0.001}}\nhole_frame: {frame}\n")
    with pytest.raises(HoleSpecError, match=words) as e:
        build_geometry(load_spec(p), "square", use_cache=False)
    assert str(p) in str(e.value) and f"'{field}'" in str(e.value)


def test_hole_at_and_hole_frame_together_are_refused(tmp_path):
    p = _write(
        tmp_path,
        "body:\n  box: {size: [0.13, 0.13, 0.07]}\nhole_at: [0, 0]\n"
        "hole_frame: {origin: [0, 0, 0.07], axis: [0, 0, 1]}\n",
    )
    with pytest.raises(HoleSpecError, match="not both") as e:
        load_spec(p)
    assert "'hole_frame'" in str(e.value)


def test_cache_keys_of_files_without_hole_frame_are_unchanged():
    """Adding the field must not invalidate users' caches: the default objects' keys are
    the ones the committed geometry was built under (BUILD_VERSION 4: the seamless hole
    walls; a version bump is the one thing meant to change them)."""
    from cfvs_maniskill.objects.build import geometry_key

    spec = load_library().specs["cuboid_test_1"]
    assert geometry_key(spec, "square", 0.004, 0.045) == "ed65b40d0dd0f4703544"
