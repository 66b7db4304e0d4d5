"""Writes the frozen generalisation set of release 1.4.0 (run once; the files are
committed).

    .venv/bin/python assets/generalisation_castings/make_bodies.py

Twelve bodies of the procedural family `castings` (cfvs_maniskill/data/shapes.py), which
the training generator never draws: cast plates and discs up to 30 cm, the opening
anywhere on the face, among a hub braced by gussets holding the opening, a channel between
two walls, a chamfered edge falling away beside it, a raised ring round it, a row of
lightening pockets. Seed 929292, never used for anything else."""

from pathlib import Path

from cfvs_maniskill.data.procedural import write_frozen_set

if __name__ == "__main__":
    here = Path(__file__).parent
    write_frozen_set(here, "castings", 929292, 12, "Frozen generalisation set (release 1.4.0)")
