"""Procedurally varied training bodies (beyond the paper): boxes, cylinders and prisms with
random dimensions and hole positions, written as ordinary hole-object files.

With `features`, each body is a mesh instead: the same primitive with things near the hole
that real parts have and the plain primitives never show the camera: a raised block (a
wall, a step, a boss) beside the hole, a notch cut out of the body (an edge or an inner
corner close to the rim), and holes anywhere their walls allow, not only near the centre.

`data/shapes.py` adds the families `ribs`, `pockets` (and counterbores), `narrow` and the
held-out `composite` and `grooved`.

The paper trains on four cuboids; here the networks can also see hundreds of distinct
bodies. Each body is a normal `assets/holes`-style YAML file (split: train), so it goes
through the same validation and geometry cache as every user file, and test objects are
never among them. Files are written once per (seed, count, peg) into the cache.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
import trimesh
import yaml

from cfvs_maniskill.constants import MIN_WALL, hole_half_extent
from cfvs_maniskill.data import shapes
from cfvs_maniskill.data.shapes import box_at, keep_clear, write_mesh_body
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


FEATURE_GAP = (0.006, 0.04)
"""Gap between the hole's edge and a raised block or a notch, metres."""
FEATURE_HEIGHT = (0.008, 0.05)
"""Height of a raised block above the top face."""


def _primitive_mesh(body: dict) -> trimesh.Trimesh:
    """The primitive as a mesh, bottom at z = 0, centred on the z axis."""
    if "box" in body:
        sx, sy, h = body["box"]["size"]
        return trimesh.creation.box([sx, sy, h], transform=_at(0, 0, h / 2))
    if "cylinder" in body:
        c = body["cylinder"]
        return trimesh.creation.cylinder(
            c["radius"], c["height"], 64, transform=_at(0, 0, c["height"] / 2)
        )
    p = body["prism"]  # a cylinder of `sides` sections is the regular prism
    return trimesh.creation.cylinder(
        p["radius"], p["height"], p["sides"], transform=_at(0, 0, p["height"] / 2)
    )


def _at(x: float, y: float, z: float) -> np.ndarray:
    return trimesh.transformations.translation_matrix([x, y, z])


def _featured_body(rng: np.random.Generator, peg: str, clearance: float, folder: Path, name: str):
    """A primitive with a raised block and/or a notch beside a hole placed anywhere: (the
    body entry of a mesh spec, hole_frame), or None when the draw left the primitive as it
    was."""
    base_body = _random_body(rng)
    base = _primitive_mesh(base_body)
    top = float(base.bounds[1, 2])
    half = hole_half_extent(peg, clearance)
    room = max(0.0, _inner_radius(base_body) - half * np.sqrt(2) - MIN_WALL)
    hole = rng.uniform(-1, 1, size=2) * room / np.sqrt(2)
    parts, cuts = [base], []
    kinds = rng.choice(["block", "notch", "both"], p=[0.45, 0.3, 0.25])
    # The feature sits on one side of the hole, `gap` beyond its edge (its square's
    # circumscribed half width, so the hole keeps its full wall whatever the peg).
    side = rng.uniform(0, 2 * np.pi)
    u = np.array([np.cos(side), np.sin(side)])
    if kinds in ("block", "both"):
        gap = rng.uniform(*FEATURE_GAP)
        depth, length = rng.uniform(0.01, 0.06), rng.uniform(0.02, 0.16)
        h = rng.uniform(*FEATURE_HEIGHT)
        c = hole + u * (half * np.sqrt(2) + gap + depth / 2)
        parts.append(box_at([depth, length, h + 0.002], [c[0], c[1], top + h / 2 - 0.001], side))
    if kinds in ("notch", "both"):
        u = -u if kinds == "both" else u  # the other side of the hole
        gap = rng.uniform(*FEATURE_GAP) + MIN_WALL
        size = 0.3
        c = hole + u * (half * np.sqrt(2) + gap + size / 2)
        # Turned a little off the direction: an inner corner, not only a straight edge.
        yaw = side + rng.uniform(-0.8, 0.8)
        # Down to the table half the time (an L-shaped body), else a step down.
        floor = -0.01 if rng.random() < 0.5 else top * rng.uniform(0.2, 0.85)
        notch = box_at([size, size, 1.0], [c[0], c[1], floor + 0.5], yaw)
        cuts.append(notch)
    mesh = trimesh.boolean.union(parts, engine="manifold") if len(parts) > 1 else base
    if cuts:
        mesh = trimesh.boolean.difference([mesh, *cuts], engine="manifold")
        if len(parts) == 1 and mesh.volume > base.volume - 1e-7:
            return None  # the notch missed the body: it would be a plain primitive
    return write_mesh_body(mesh, hole, top, folder, name)


PART_HEIGHT = (0.1, 0.26)
"""Height of a `parts` body: real parts put the opening well above the 5-12 cm of the
primitives (the fandisk CAD part's is 13-22 cm above the table)."""
PART_SLOPE_DEG = (15.0, 65.0)
"""Inclination of a `parts` body's planar cuts from the horizontal."""


def _part_body(rng: np.random.Generator, peg: str, clearance: float, folder: Path, name: str):
    """A tall primitive cut like a machined part: the hole on what is left of the top face,
    one to three inclined planar faces falling away from it (a chamfer, a sloped flank,
    a ridge), and a curved boss (a lying cylinder or a ball) beside or below it. (the body
    entry of a mesh spec, hole_frame)."""
    base_body = _random_body(rng)
    key = next(iter(base_body))
    h = round(float(rng.uniform(*PART_HEIGHT)), 4)
    if key == "box":
        base_body["box"]["size"][2] = h
    else:
        base_body[key]["height"] = h
    base = _primitive_mesh(base_body)
    keep = keep_clear(peg, clearance)  # the opening's corner plus a wall
    room = max(0.0, _inner_radius(base_body) - keep)
    hole = rng.uniform(-1, 1, size=2) * room * 0.8 / np.sqrt(2)
    mesh = base
    for _ in range(int(rng.integers(1, 4))):
        # A half-space whose boundary meets the top face `gap` beyond the opening and
        # falls away from it at `slope`: everything above it goes.
        side = rng.uniform(0, 2 * np.pi)
        u = np.array([np.cos(side), np.sin(side), 0.0])
        slope = np.radians(rng.uniform(*PART_SLOPE_DEG))
        gap = rng.uniform(0.004, 0.05)
        n = np.array([u[0] * np.sin(slope), u[1] * np.sin(slope), np.cos(slope)])
        p = np.array([hole[0], hole[1], h]) + u * (keep + gap)
        # A 1 m cube whose bottom face lies on the plane.
        cut = trimesh.creation.box([1.0, 1.0, 1.0], transform=_at(0, 0, 0.5))
        z = np.array([0.0, 0.0, 1.0])
        cut.apply_transform(trimesh.geometry.align_vectors(z, n))
        cut.apply_translation(p)
        trimmed = trimesh.boolean.difference([mesh, cut], engine="manifold")
        if trimmed.volume > 0.3 * base.volume:
            mesh = trimmed
    if rng.random() < 0.7:
        # A curved boss beside the hole, its top below the opening (it must not hide it).
        side = rng.uniform(0, 2 * np.pi)
        u = np.array([np.cos(side), np.sin(side)])
        r = rng.uniform(0.02, 0.07)
        top = h - rng.uniform(0.01, 0.08)
        c = hole + u * (keep + rng.uniform(0.01, 0.05) + r)
        zc = max(top - r, r * 0.3)
        if rng.random() < 0.5:
            boss = trimesh.creation.icosphere(subdivisions=3, radius=r)
        else:
            boss = trimesh.creation.cylinder(r, rng.uniform(0.04, 0.16), 48)
            boss.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
            boss.apply_transform(
                trimesh.transformations.rotation_matrix(side + np.pi / 2, [0, 0, 1])
            )
        boss.apply_translation([c[0], c[1], zc])
        mesh = trimesh.boolean.union([mesh, boss], engine="manifold")
        floor = trimesh.creation.box([1.0, 1.0, 1.0], transform=_at(0, 0, -0.5))
        mesh = trimesh.boolean.difference([mesh, floor], engine="manifold")  # flat bottom
    return write_mesh_body(mesh, hole, h, folder, name)


FAMILIES = {
    "plain": "",
    "features": "f",
    "parts": "p",
    "ribs": "r",
    "pockets": "k",
    "narrow": "n",
    "composite": "c",
    "grooved": "g",
    "plates": "l",
    "fixtures": "x",
    "housings": "h",
    "manifolds": "m",
    "stands": "s",
    "castings": "a",
    "decoys": "d",
    "wheels": "w",
    "links": "v",
}
"""Procedural body families and their file-name tags."""
MESH_FAMILIES = {"features": _featured_body, "parts": _part_body, **shapes.FAMILIES}
"""The families drawn as meshes, by the function that draws one (None: no body this draw)."""
TRAINING_FAMILIES = tuple(f for f in FAMILIES if f not in shapes.HELD_OUT_FAMILIES)


def check_family(family: str, split: str = "train") -> None:
    """ValueError unless `family` may be drawn for `split` (training: not a held-out one)."""
    allowed = TRAINING_FAMILIES if split == "train" else tuple(FAMILIES)
    if family not in allowed:
        held = " (held out of training: the generalisation set's)" if family in FAMILIES else ""
        raise ValueError(f"expected one of {list(allowed)}, got {family!r}{held}")


def procedural_specs(
    count: int,
    seed: int,
    peg: str,
    clearance: float,
    depth: float,
    family: str = "plain",
    split: str = "train",
    folder: Path | None = None,
) -> tuple[Path, list[str]]:
    """Write (once) `count` valid bodies of `family` for `peg`; return their folder and
    names. Training bodies (split train) come from `TRAINING_FAMILIES` only; the held-out
    family is written with split test, for the frozen generalisation set."""
    try:
        check_family(family, split)
    except ValueError as e:
        raise ValueError(f"procedural family: {e}") from None
    tag = f"-{family}" if family != "plain" else ""
    if folder is None:
        name = f"{peg}-c{clearance:g}-d{depth:g}-s{seed}-n{count}{tag}"
        folder = cache_dir().parent / "procedural" / name
    names = [f"proc{FAMILIES[family]}_{seed}_{i:04d}" for i in range(count)]
    if all((folder / f"{n}.yaml").is_file() for n in names):
        return folder, names
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    for name in names:
        path = folder / f"{name}.yaml"
        for _ in range(200):
            if family in MESH_FAMILIES:
                drawn = MESH_FAMILIES[family](rng, peg, clearance, folder, name)
                if drawn is None:
                    continue
                body, frame = drawn
                where = {"hole_frame": frame}
            else:
                body = _random_body(rng)
                # Room for the hole's centre to move: the top face minus a hole and a wall.
                room = max(0.0, _inner_radius(body) - 0.03)
                shift = rng.uniform(-1, 1, size=2) * HOLE_SHIFT * room / np.sqrt(2)
                where = {"hole_at": [round(float(v), 4) for v in shift]}
            grey = float(rng.uniform(0.35, 0.8))
            tint = rng.uniform(-0.08, 0.08, size=3)
            doc = {
                "split": split,
                "hole": [peg],
                "body": body,
                **where,
                "color": [round(float(np.clip(grey + t, 0, 1)), 3) for t in tint],
            }
            spec = parse_spec(doc, path)
            try:
                build_geometry(spec, peg, clearance, depth)  # checks room; fills the cache
            except HoleSpecError:
                continue  # too small for the hole: draw another body
            tmp = path.with_suffix(".tmp")
            head = "training body" if split == "train" else f"{family} body, split {split}"
            tmp.write_text(f"# procedural {head} (seed {seed})\n" + yaml.safe_dump(doc))
            os.replace(tmp, path)
            break
        else:
            raise RuntimeError(f"could not draw a valid procedural body for {name}")
    return folder, names


def write_frozen_set(here: Path, family: str, seed: int, count: int, title: str) -> None:
    """Write a frozen generalisation set into folder `here`: `count` bodies of held-out
    `family` drawn from `seed`, as `gen_<family>_NN.stl` / `.yaml` files (split test) that
    host both pegs (drawn for the square peg at 4 mm clearance, the widest opening of the
    default tasks). `title` heads each file."""
    with tempfile.TemporaryDirectory() as tmp:
        folder, names = procedural_specs(
            count, seed, "square", 0.004, 0.045, family, split="test", folder=Path(tmp)
        )
        for i, n in enumerate(names):
            doc = yaml.safe_load((folder / f"{n}.yaml").read_text())
            name = f"gen_{family}_{i:02d}"
            shutil.copy(folder / doc["body"]["mesh"]["file"], here / f"{name}.stl")
            doc.update(name=name, hole=["round", "square"], body={"mesh": {"file": f"{name}.stl"}})
            path = here / f"{name}.yaml"
            head = f"# {title}: {family} body {i}, seed {seed}.\n"
            path.write_text(head + yaml.safe_dump(doc, sort_keys=False))
            spec = parse_spec(doc, path)
            for peg in ("round", "square"):
                build_geometry(spec, peg, 0.004, 0.045)  # hosts both pegs
            print(name, "ok")
