"""Writes the successor frozen generalisation set (run once; the files are committed).

    .venv/bin/python assets/generalisation_grooved/make_bodies.py

Twelve bodies of the procedural family `grooved` (cfvs_maniskill/data/shapes.py), which
the training generator never draws: a box or a disc with V-grooves and square slots cut
across its face beside the opening, a counterbore a third of the time. Seed 515151, never
used for anything else."""

from pathlib import Path

from cfvs_maniskill.data.procedural import write_frozen_set

if __name__ == "__main__":
    here = Path(__file__).parent
    write_frozen_set(here, "grooved", 515151, 12, "Frozen generalisation set (successor)")
