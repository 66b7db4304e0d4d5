"""Every way a hole-object file can be wrong gives an error naming the file and the field."""

from __future__ import annotations

import pytest

from cfvs_maniskill.objects.build import build_geometry
from cfvs_maniskill.objects.library import SelectionError, load_library
from cfvs_maniskill.objects.spec import HoleSpecError, load_spec

from .conftest import run_cli

BOX = "body:\n  box: {size: [0.13, 0.13, 0.07]}\n"


def _write(tmp_path, text: str, name: str = "thing.yaml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def _open_box_obj(path):
    import trimesh

    m = trimesh.creation.box([0.1, 0.1, 0.07])
    m.update_faces(list(range(len(m.faces) - 2)))  # drop one side: open edges
    m.export(path)


@pytest.mark.parametrize(
    ("text", "field", "words"),
    [
        (BOX + "colour: [1, 0, 0]\n", "colour", "unknown key"),
        ("split: test\n", "body", "missing"),
        ("body:\n  box: {size: [0.13, 0.13]}\n", "body.box.size", "list of 3"),
        ("body:\n  box: {size: [0.13, -0.13, 0.07]}\n", "body.box.size.1", "> 0"),
        ("body:\n  box: {size: 0.1}\n", "body.box.size", "list of 3"),
        (
            "body:\n  cylinder: {radius: '7cm', height: 0.07}\n",
            "body.cylinder.radius",
            "expected a number",
        ),
        ("body:\n  cylinder: {height: 0.07}\n", "body.cylinder.radius", "missing"),
        (
            "body:\n  prism: {sides: 2, radius: 0.07, height: 0.07}\n",
            "body.prism.sides",
            ">= 3",
        ),
        (
            "body:\n  box: {size: [0.1, 0.1, 0.1]}\n  cylinder: {radius: 0.07, height: 0.07}\n",
            "body",
            "exactly one",
        ),
        ("body:\n  sphere: {radius: 0.1}\n", "body.sphere", "unknown body kind"),
        ("body:\n  box: {size: [0.1, 0.1, 0.1], colour: 1}\n", "body.box.colour", "unknown key"),
        (BOX + "split: validation\n", "split", "'train' or 'test'"),
        (BOX + "hole: [hexagonal]\n", "hole.0", "'round' or 'square'"),
        (BOX + "hole_at: [0.0]\n", "hole_at", "list of 2"),
        (BOX + "color: [2, 0, 0]\n", "color.0", "<= 1"),
        ("body:\n  mesh: {file: nowhere.obj}\n", "body.mesh.file", "not found"),
        ("body:\n  mesh: {file: part.step}\n", "body.mesh.file", ".obj/.stl/.ply"),
        ("- just\n- a list\n", "<top>", "mapping"),
        ("body: {box: {size: [0.1, 0.1\n", "<top>", "not valid YAML"),
    ],
)
def test_spec_errors_name_file_and_field(tmp_path, text, field, words):
    p = _write(tmp_path, text)
    with pytest.raises(HoleSpecError) as e:
        load_spec(p)
    msg = str(e.value)
    assert str(p) in msg and f"'{field}'" in msg and words in msg, msg


@pytest.mark.parametrize(
    ("body", "field", "words"),
    [
        ("box: {size: [0.054, 0.13, 0.07]}", "body.box.size", "mm missing"),  # too narrow
        ("cylinder: {radius: 0.03, height: 0.07}", "body.cylinder", "mm missing"),  # too small
        ("box: {size: [0.13, 0.13, 0.04]}", "body.box.size", "deeper than the body"),  # thin
    ],
)
def test_bodies_without_room_for_the_hole_say_how_much_is_missing(tmp_path, body, field, words):
    p = _write(tmp_path, f"body:\n  {body}\n")
    with pytest.raises(HoleSpecError) as e:
        build_geometry(load_spec(p), "square")
    msg = str(e.value)
    assert str(p) in msg and f"'{field}'" in msg and words in msg, msg


def test_hole_at_off_the_body(tmp_path):
    p = _write(tmp_path, BOX + "hole_at: [0.5, 0.0]\n")
    with pytest.raises(HoleSpecError, match="'hole_at'"):
        build_geometry(load_spec(p), "round")


def test_bad_mesh_files(tmp_path):
    (tmp_path / "junk.obj").write_bytes(b"\x00\x01 this is not a mesh \xff" * 50)
    p = _write(tmp_path, "body:\n  mesh: {file: junk.obj}\n", "junk.yaml")
    with pytest.raises(HoleSpecError) as e:
        build_geometry(load_spec(p), "round")
    assert str(p) in str(e.value) and "'body.mesh.file'" in str(e.value)

    _open_box_obj(tmp_path / "open.obj")
    p = _write(tmp_path, "body:\n  mesh: {file: open.obj}\n", "open.yaml")
    with pytest.raises(HoleSpecError, match="not watertight") as e:
        build_geometry(load_spec(p), "round")
    assert str(p) in str(e.value) and "'body.mesh.file'" in str(e.value)


def test_one_bad_file_never_hides_the_others(tmp_path):
    _write(tmp_path, BOX, "good.yaml")
    _write(tmp_path, "body: 3\n", "bad.yaml")
    _write(tmp_path, BOX + "name: cylinder\n", "dup.yaml")  # clashes with a default object
    lib = load_library([tmp_path])
    assert "good" in lib.specs and "cylinder" in lib.specs
    files = sorted(e.file.rsplit("/", 1)[-1] for e in lib.errors)
    assert files == ["bad.yaml", "dup.yaml"]
    with pytest.raises(SelectionError, match="valid: all, train, test, .*cuboid_test_1"):
        lib.select(["no_such_object"])
    with pytest.raises(SelectionError, match="invalid"):
        lib.select(["bad"])


def test_assets_check_command_prints_a_table(tmp_path):
    _write(
        tmp_path,
        "split: train\nhole: square\nbody:\n  prism: {sides: 6, radius: 0.07, height: 0.06}\n",
        "hexagon.yaml",
    )
    _write(tmp_path, "body:\n  box: {size: [0.05, 0.05, 0.05]}\n", "tiny.yaml")
    r = run_cli("cfvs_maniskill.assets", "check", str(tmp_path))
    assert r.returncode == 1, r.stderr
    # The table wraps long cells (a long tmp path moves the wrap): read it as running text.
    out = " ".join(r.stdout.replace("│", " ").split())
    for word in (
        "hexagon",
        "6-prism",
        "square 5",
        "tiny",
        "mm missing",
        "pentagonal_prism",
        "9 ok, 1 with errors",
    ):
        assert word in out, out
    r = run_cli("cfvs_maniskill.assets", "check")
    assert r.returncode == 0 and "8 ok, 0 with errors" in r.stdout


def test_degenerate_mesh_is_named(tmp_path):
    import trimesh

    # Closed but flat: a box of zero height has no inside to cut a hole from.
    trimesh.creation.box([0.1, 0.1, 0.0]).export(tmp_path / "flat.stl")
    p = _write(tmp_path, "body:\n  mesh: {file: flat.stl}\n", "flat.yaml")
    with pytest.raises(HoleSpecError) as e:
        build_geometry(load_spec(p), "round")
    assert str(p) in str(e.value) and "'body.mesh.file'" in str(e.value)
    assert "flat.stl" in str(e.value)
