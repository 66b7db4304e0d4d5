"""Writes the frozen generalisation set of issue 42 (run once; the files are committed).

    .venv/bin/python assets/generalisation/make_bodies.py

Twelve bodies of the procedural family `composite` (cfvs_maniskill/data/shapes.py), which
the training generator never draws: L, T and U outlines carrying two or three of ribs,
pockets, counterbores and steps, a boss round the opening half the time. Seed 424242,
never used for anything else. Each body is drawn for the square peg at 4 mm clearance
(the widest opening of the default tasks), so it hosts both pegs."""

from pathlib import Path

from cfvs_maniskill.data.procedural import write_frozen_set

if __name__ == "__main__":
    here = Path(__file__).parent
    write_frozen_set(here, "composite", 424242, 12, "Frozen generalisation set (issue 42)")
