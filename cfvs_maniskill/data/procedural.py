"""Procedurally varied training bodies (beyond the paper): boxes, cylinders and prisms with
random dimensions and hole positions, written as ordinary hole-object files.

The paper trains on four cuboids; here the networks can also see hundreds of distinct
bodies. Each body is a normal `assets/holes`-style YAML file (split: train), so it goes
through the same validation and geometry cache as every user file, and test objects are
never among them. Files are written once per (seed, count, peg) into the cache.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import yaml

from cfvs_maniskill.objects.build import build_geometry, cache_dir
from cfvs_maniskill.objects.spec import HoleSpecError, parse_spec

BOX_SIDE = (0.085, 0.22)
CYLINDER_RADIUS = (0.045, 0.11)
PRISM_SIDES = (3, 8)
PRISM_RADIUS = (0.055, 0.12)
HEIGHT = (0.052, 0.12)
HOLE_SHIFT = 0.35
"""The hole may sit off the top face's centre by up to this fraction of the room left."""


def _random_body(rng: np.random.Generator) -> dict:
    kind = rng.choice(["box", "cylinder", "prism"])
    h = round(float(rng.uniform(*HEIGHT)), 4)
    if kind == "box":
        sx, sy = (round(float(v), 4) for v in rng.uniform(*BOX_SIDE, size=2))
        return {"box": {"size": [sx, sy, h]}}
    if kind == "cylinder":
        return {"cylinder": {"radius": round(float(rng.uniform(*CYLINDER_RADIUS)), 4), "height": h}}
    sides = int(rng.integers(PRISM_SIDES[0], PRISM_SIDES[1] + 1))
    r = round(float(rng.uniform(*PRISM_RADIUS)), 4)
    return {"prism": {"sides": sides, "radius": r, "height": h}}


def _inner_radius(body: dict) -> float:
    """Radius of the largest centred disc on the top face."""
    if "box" in body:
        return min(body["box"]["size"][:2]) / 2
    if "cylinder" in body:
        return body["cylinder"]["radius"]
    p = body["prism"]
    return p["radius"] * np.cos(np.pi / p["sides"])


def procedural_specs(
    count: int, seed: int, peg: str, clearance: float, depth: float
) -> tuple[Path, list[str]]:
    """Write (once) `count` valid training bodies for `peg`; return their folder and names."""
    folder = cache_dir().parent / "procedural" / f"{peg}-c{clearance:g}-d{depth:g}-s{seed}-n{count}"
    names = [f"proc_{seed}_{i:04d}" for i in range(count)]
    if all((folder / f"{n}.yaml").is_file() for n in names):
        return folder, names
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    for name in names:
        path = folder / f"{name}.yaml"
        for _ in range(200):
            body = _random_body(rng)
            # Room for the hole's centre to move: the top face minus a hole and a wall.
            room = max(0.0, _inner_radius(body) - 0.03)
            shift = rng.uniform(-1, 1, size=2) * HOLE_SHIFT * room / np.sqrt(2)
            grey = float(rng.uniform(0.35, 0.8))
            tint = rng.uniform(-0.08, 0.08, size=3)
            doc = {
                "split": "train",
                "hole": [peg],
                "body": body,
                "hole_at": [round(float(v), 4) for v in shift],
                "color": [round(float(np.clip(grey + t, 0, 1)), 3) for t in tint],
            }
            spec = parse_spec(doc, path)
            try:
                build_geometry(spec, peg, clearance, depth)  # checks room; fills the cache
            except HoleSpecError:
                continue  # too small for the hole: draw another body
            tmp = path.with_suffix(".tmp")
            tmp.write_text(f"# procedural training body (seed {seed})\n" + yaml.safe_dump(doc))
            os.replace(tmp, path)
            break
        else:
            raise RuntimeError(f"could not draw a valid procedural body for {name}")
    return folder, names
