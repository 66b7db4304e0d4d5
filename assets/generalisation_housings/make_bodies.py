"""Writes the frozen generalisation set of release 1.2.0 (run once; the files are
committed).

    .venv/bin/python assets/generalisation_housings/make_bodies.py

Twelve bodies of the procedural family `housings` (cfvs_maniskill/data/shapes.py), which
the training generator never draws: housing blocks and discs up to 30 cm with the opening
anywhere on the face, among a countersink, a tower, a slot, a braced bracket, ribs or a
wall. Seed 818181, never used for anything else."""

from pathlib import Path

from cfvs_maniskill.data.procedural import write_frozen_set

if __name__ == "__main__":
    here = Path(__file__).parent
    write_frozen_set(here, "housings", 818181, 12, "Frozen generalisation set (release 1.2.0)")
