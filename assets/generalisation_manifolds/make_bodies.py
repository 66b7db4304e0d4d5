"""Writes the frozen generalisation set of release 1.3.0 (run once; the files are
committed).

    .venv/bin/python assets/generalisation_manifolds/make_bodies.py

Twelve bodies of the procedural family `manifolds` (cfvs_maniskill/data/shapes.py), which
the training generator never draws: manifold blocks and discs up to 30 cm, or round bars
with a flat milled along the top, the opening anywhere on the face, among a face-seal
groove round it, ports wider than it, hex fittings with bores, a long shallow recess with
the opening at one end, a wall. Seed 919191, never used for anything else."""

from pathlib import Path

from cfvs_maniskill.data.procedural import write_frozen_set

if __name__ == "__main__":
    here = Path(__file__).parent
    write_frozen_set(here, "manifolds", 919191, 12, "Frozen generalisation set (release 1.3.0)")
