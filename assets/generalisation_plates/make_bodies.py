"""Writes the frozen generalisation set of the release after v3 (run once; the files are
committed).

    .venv/bin/python assets/generalisation_plates/make_bodies.py

Twelve bodies of the procedural family `plates` (cfvs_maniskill/data/shapes.py), which
the training generator never draws: plates up to 30 cm wide with the opening far from
their centre, beside a wall or a step, on a small island or among decoy openings of other
sizes. Seed 626262, never used for anything else."""

from pathlib import Path

from cfvs_maniskill.data.procedural import write_frozen_set

if __name__ == "__main__":
    here = Path(__file__).parent
    write_frozen_set(here, "plates", 626262, 12, "Frozen generalisation set (release v4)")
