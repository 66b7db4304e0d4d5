"""Writes the frozen generalisation set of release 1.6.0 (run once; the files are
committed).

    .venv/bin/python assets/generalisation_links/make_bodies.py

Twelve bodies of the procedural family `links` (cfvs_maniskill/data/shapes.py), which the
training generator never draws: links, levers and bellcranks up to 30 cm across, one to
three arms from a pivot boss, the opening at the pivot or an arm's end, among an I-beam's
recessed web, a knurled pad, a slot aimed at the opening, bores through the arms' other ends, a
boss lifting the opening. Seed 949494, never used for anything else."""

from pathlib import Path

from cfvs_maniskill.data.procedural import write_frozen_set

if __name__ == "__main__":
    here = Path(__file__).parent
    write_frozen_set(here, "links", 949494, 12, "Frozen generalisation set (release 1.6.0)")
