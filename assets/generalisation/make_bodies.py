"""Writes the frozen generalisation set of issue 42 (run once; the files are committed).

    .venv/bin/python assets/generalisation/make_bodies.py

Twelve bodies of the procedural family `composite` (cfvs_maniskill/data/shapes.py), which
the training generator never draws: L, T and U outlines carrying two or three of ribs,
pockets, counterbores and steps, a boss round the opening half the time. Seed 424242,
never used for anything else. Each body is drawn for the square peg at 4 mm clearance
(the widest opening of the default tasks), so it hosts both pegs."""

import shutil
import tempfile
from pathlib import Path

import yaml

from cfvs_maniskill.data.procedural import procedural_specs
from cfvs_maniskill.objects.build import build_geometry
from cfvs_maniskill.objects.spec import parse_spec

HERE = Path(__file__).parent
SEED, COUNT = 424242, 12


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder, names = procedural_specs(
            COUNT, SEED, "square", 0.004, 0.045, "composite", split="test", folder=Path(tmp)
        )
        for i, n in enumerate(names):
            doc = yaml.safe_load((folder / f"{n}.yaml").read_text())
            name = f"gen_composite_{i:02d}"
            shutil.copy(folder / doc["body"]["mesh"]["file"], HERE / f"{name}.stl")
            doc.update(name=name, hole=["round", "square"], body={"mesh": {"file": f"{name}.stl"}})
            path = HERE / f"{name}.yaml"
            head = f"# Frozen generalisation set (issue 42): composite body {i}, seed {SEED}.\n"
            path.write_text(head + yaml.safe_dump(doc, sort_keys=False))
            spec = parse_spec(doc, path)
            for peg in ("round", "square"):
                build_geometry(spec, peg, 0.004, 0.045)  # hosts both pegs
            print(name, "ok")


if __name__ == "__main__":
    main()
