"""Writes the frozen generalisation set of release 1.1.0 (run once; the files are
committed).

    .venv/bin/python assets/generalisation_fixtures/make_bodies.py

Twelve bodies of the procedural family `fixtures` (cfvs_maniskill/data/shapes.py), which
the training generator never draws: fixture plates and flanges up to 28 cm with the opening
anywhere on the face, among a bolt circle, dowel pins, a ramp, a wall, a step down or an
island. Seed 717171, never used for anything else."""

from pathlib import Path

from cfvs_maniskill.data.procedural import write_frozen_set

if __name__ == "__main__":
    here = Path(__file__).parent
    write_frozen_set(here, "fixtures", 717171, 12, "Frozen generalisation set (release 1.1.0)")
