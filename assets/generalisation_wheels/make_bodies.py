"""Writes the frozen generalisation set of release 1.5.0 (run once; the files are
committed).

    .venv/bin/python assets/generalisation_wheels/make_bodies.py

Twelve bodies of the procedural family `wheels` (cfvs_maniskill/data/shapes.py), which the
training generator never draws: wheels, pulleys and gear blanks 10-30 cm across, the
opening at the centre or anywhere on the face, among round windows through the part round
it, a web recessed between spokes round its hub, radial ribs, a rim standing round the
edge, gear teeth. Seed 939393, never used for anything else."""

from pathlib import Path

from cfvs_maniskill.data.procedural import write_frozen_set

if __name__ == "__main__":
    here = Path(__file__).parent
    write_frozen_set(here, "wheels", 939393, 12, "Frozen generalisation set (release 1.5.0)")
