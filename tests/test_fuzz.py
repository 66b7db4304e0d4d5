"""Every field of every file kind a user writes, set to a wrong type, NaN, a negative or a
huge number, or left out: a named error or (where the field allows it) a load, never a
traceback (tests/fuzz_files.py); and the table in tests/FUZZ.md is today's."""

from __future__ import annotations

import pytest

from .conftest import ROOT
from .fuzz_files import cases, expected, run_case, table

CASES = cases()


@pytest.mark.parametrize(
    ("kind", "path", "bad"),
    CASES,
    ids=[f"{k.name}:{'.'.join(map(str, p))}:{b}" for k, p, b in CASES],
)
def test_bad_field_is_named_never_a_traceback(kind, path, bad):
    outcome, message = run_case(kind, path, bad)
    assert outcome in expected(path, bad, kind), f"{outcome}: {message}"


def test_every_file_kind_and_field_is_fuzzed():
    kinds = {k.name for k, _, _ in CASES}
    assert {"task file", "sensor profile", "hole object", "hole object (mesh)"} <= kinds
    fields = {".".join(map(str, p)) for _, p, _ in CASES}
    for f in ("camera_width", "objects", "init_error", "depth.edge_flying", "wrench.torque_bias",
              "imager.stereo_baseline", "body.prism.sides", "body.mesh.scale", "hole_frame.axis",
              "color"):  # fmt: skip
        assert f in fields, f


def test_fuzz_page_has_todays_table():
    doc = (ROOT / "tests" / "FUZZ.md").read_text()
    assert table() in doc, "run `python -m tests.fuzz_files` to rewrite tests/FUZZ.md"
