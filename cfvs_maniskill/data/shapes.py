"""More procedural body families: the details real parts put around an opening.

Each family draws one mesh body with a hole frame, like `procedural._featured_body`:
- `ribs`: thin parallel ribs (2-5 mm) standing on the face beside the hole;
- `pockets`: blind pockets, smaller openings that do not fit the peg, and a counterbore
  (the opening at the floor of a wide shallow recess) around the hole;
- `narrow`: narrow, tall bodies, the hole near an end or an inner corner;
- `composite`: an L-, T- or U-shaped outline carrying two or three of the elements above
  plus a boss around the opening. Training never draws it (`TRAINING_FAMILIES`): the
  frozen generalisation set (`assets/generalisation/`) is made of it;
- `grooved`: a box or disc with V-grooves and square slots cut across its face beside the
  opening, from edge to edge: long straight recessed edges, which no training family has.
  Held out too: the successor frozen set (`assets/generalisation_grooved/`) is made of it;
- `plates`: plates up to 30 cm wide, the opening far from their centre, with a wall or a
  step 1-4 cm beside it, the opening on a small island, or decoy openings of other sizes.
  Held out: release 1.0.0's frozen set (`assets/generalisation_plates/`) is made of it.
- `fixtures`: fixture plates and flanges up to 28 cm, the opening anywhere on the face,
  with two or three of: a bolt circle of small drilled holes round the opening, dowel pins
  or posts standing beside it, a ramp rising beside it, a wall, a step down, an island.
  Held out: release 1.1.0's frozen set (`assets/generalisation_fixtures/`) is made of it.
- `housings`: housing blocks and discs up to 30 cm, the opening anywhere on the face, with
  two or three of: the opening countersunk (a cone round its edge), on a tower 4-12 cm
  tall, an elongated slot beside it, a bracket (a wall braced by sloped gussets) facing
  it, ribs, a wall. Held out: release 1.2.0's frozen set (`assets/generalisation_housings/`)
  is made of it.
- `manifolds`: manifold blocks and discs up to 30 cm, or round bars with a flat milled
  along the top (the surface falling away beside the opening), with two or three of: a
  face-seal groove round the opening, ports wider than it, hex fittings with bores standing
  beside it, the opening at one end of a long shallow recess, a wall. Held out: release
  1.3.0's frozen set (`assets/generalisation_manifolds/`) is made of it.
- `stands`: plates and discs 8-30 cm across carrying posts and blocks 1-13 cm tall (some
  with a bore of another size in their top), walls, ribs, pockets or a step, and most of
  the time the opening itself on a riser 1-13 cm above the face: the opening need not be
  on the body's largest face, and a tall thing beside it need not hold it. A training
  family: the coarse network's bodies otherwise never raise the opening above the rest.
- `decoys`: plates and discs 8-30 cm across, the opening anywhere on the face, with one to
  three blind openings the peg does not fit (round or square, half to nearly twice its
  width, 1-12 cm from it) and up to two of: a wall, a step, pockets, ribs, a counterbore.
  A training family: the coarse network's other bodies never show an opening wider than
  the peg's, so it had no reason to tell one from the peg's own.
- `castings`: cast plates and discs up to 30 cm, the opening anywhere on the face, with two
  or three of: the opening on a hub braced by gussets, in a channel between two walls, a
  chamfered edge falling away beside it, a raised ring round it, a row of lightening
  pockets. Held out: release 1.4.0's frozen set (`assets/generalisation_castings/`) is
  made of it.
- `wheels`: wheels, pulleys and gear blanks 10-30 cm across, the opening at the centre or
  anywhere on the face, with two or three of: round windows through the part round the
  opening (the table seen through them), the web round a hub recessed between spokes,
  radial ribs, a rim standing round the edge, gear teeth. Held out: release 1.5.0's frozen
  set (`assets/generalisation_wheels/`) is made of it.
- `links`: links, levers and bellcranks up to 30 cm across, one to three arms from a pivot
  boss, the opening at the pivot or an arm's end, with two or three of: the arms' web
  recessed inside flanges (an I-section), a knurled pad round the opening, a slot through
  the part aimed at it, bores through the arms' other ends, a boss lifting the opening.
  Held out: release 1.6.0's frozen set (`assets/generalisation_links/`) is made of it.

Sizes keep the hole's full wall: everything stays `keep` (the opening's circumscribed
radius plus `MIN_WALL`) away from the hole's axis.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from pathlib import Path

import manifold3d as mf
import numpy as np
import trimesh

from cfvs_maniskill.constants import MIN_WALL, hole_half_extent
from cfvs_maniskill.objects import build

Draw = Callable[[np.random.Generator, str, float, Path, str], "tuple[dict, dict] | None"]


def box_at(size, centre, yaw: float = 0.0) -> trimesh.Trimesh:
    """A box of `size` turned by `yaw` about z, its centre at `centre`."""
    box = trimesh.creation.box(size)
    box.apply_transform(trimesh.transformations.rotation_matrix(yaw, [0, 0, 1]))
    box.apply_translation(centre)
    return box


def _union(meshes: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    return trimesh.boolean.union(meshes, engine="manifold") if len(meshes) > 1 else meshes[0]


def _minus(mesh: trimesh.Trimesh, cuts: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    return trimesh.boolean.difference([mesh, *cuts], engine="manifold") if cuts else mesh


def keep_clear(peg: str, clearance: float) -> float:
    """Distance from the hole's axis that every element keeps clear."""
    return hole_half_extent(peg, clearance) * np.sqrt(2) + MIN_WALL


def _unit(angle: float) -> np.ndarray:
    return np.array([np.cos(angle), np.sin(angle)])


def add_ribs(rng, mesh, hole, top, keep):
    """One to four thin parallel ribs beside the hole, 5-40 mm tall."""
    side = rng.uniform(0, 2 * np.pi)
    u = _unit(side)
    gap = keep + rng.uniform(0.004, 0.03)
    pitch = rng.uniform(0.008, 0.025)
    height, thick = rng.uniform(0.005, 0.04), rng.uniform(0.002, 0.005)
    length = rng.uniform(0.03, 0.15)
    ribs = []
    for k in range(int(rng.integers(1, 5))):
        c = hole + u * (gap + k * pitch)
        ribs.append(box_at([thick, length, height + 0.002], [*c, top + height / 2 - 0.001], side))
    return _union([mesh, *ribs]), top


def add_pockets(rng, mesh, hole, top, keep):
    """One to three blind pockets (square or round) and small drilled openings, none wide
    enough for the peg, beside the hole."""
    cuts = []
    for _ in range(int(rng.integers(1, 4))):
        u = _unit(rng.uniform(0, 2 * np.pi))
        if rng.random() < 0.5:  # a drilled opening, narrower than any peg
            r = rng.uniform(0.002, 0.012)
            c = hole + u * (keep + MIN_WALL + r + rng.uniform(0.0, 0.03))
            d = rng.uniform(0.01, 0.03)
            cut = trimesh.creation.cylinder(r, 2 * d, 32)
            cut.apply_translation([*c, top])
        else:  # a pocket
            w, length = rng.uniform(0.006, 0.025), rng.uniform(0.01, 0.05)
            c = hole + u * (keep + MIN_WALL + max(w, length) / 2 + rng.uniform(0.0, 0.03))
            d = rng.uniform(0.003, 0.02)
            cut = box_at([w, length, 2 * d], [*c, top], rng.uniform(0, np.pi))
        cuts.append(cut)
    return _minus(mesh, cuts), top


def add_counterbore(rng, mesh, hole, top, keep):
    """The opening at the floor of a round or square recess 3-12 mm deep."""
    d = rng.uniform(0.003, 0.012)
    r = keep + rng.uniform(0.004, 0.015)
    if rng.random() < 0.5:
        cut = trimesh.creation.cylinder(r, 2 * d, 64)
        cut.apply_translation([*hole, top])
    else:
        cut = box_at([2 * r, 2 * r, 2 * d], [*hole, top], rng.uniform(0, np.pi / 2))
    return _minus(mesh, [cut]), top - d


def add_boss(rng, mesh, hole, top, keep):
    """A round boss around the opening, 4-20 mm above the face: the opening on its top."""
    h = rng.uniform(0.004, 0.02)
    r = keep + rng.uniform(0.002, 0.012)
    boss = trimesh.creation.cylinder(r, h + 0.002, 64)
    boss.apply_translation([*hole, top + h / 2 - 0.001])
    return _union([mesh, boss]), top + h


def _step_down(rng, mesh, hole, top, keep, gap: tuple[float, float], size: float, turn: float):
    """A `size`-wide notch, to the table or part of the way, `gap` (m) from the opening's
    wall, turned up to `turn` (rad) off facing the hole."""
    side = rng.uniform(0, 2 * np.pi)
    c = hole + _unit(side) * (keep + rng.uniform(*gap) + size / 2)
    floor = -0.01 if rng.random() < 0.4 else top * rng.uniform(0.3, 0.85)
    notch = box_at([size, size, 1.0], [*c, floor + 0.5], side + rng.uniform(-turn, turn))
    return _minus(mesh, [notch]), top


def add_step(rng, mesh, hole, top, keep):
    """A step down (or to the table) next to the hole: an edge or an inner corner."""
    return _step_down(rng, mesh, hole, top, keep, (0.002, 0.03), 0.3, 0.8)


def _slab(rng, keep: float, height: float) -> tuple[trimesh.Trimesh, np.ndarray]:
    """A box with room for the hole: (mesh, hole x y)."""
    sx, sy = rng.uniform(2 * keep + 0.01, 0.2, size=2)
    room = np.array([sx, sy]) / 2 - keep
    hole = rng.uniform(-1, 1, size=2) * room
    return box_at([sx, sy, height], [0, 0, height / 2]), hole


def write_mesh_body(mesh: trimesh.Trimesh, hole: np.ndarray, top: float, folder: Path, name: str):
    """Export a drawn body as `name`.stl: (its mesh spec entry, the hole frame of an opening
    at `hole` (x, y) on the face at height `top`, axis up)."""
    mesh.export(folder / f"{name}.stl")
    frame = {
        "origin": [round(float(hole[0]), 5), round(float(hole[1]), 5), round(float(top), 5)],
        "axis": [0.0, 0.0, 1.0],
    }
    return {"mesh": {"file": f"{name}.stl"}}, frame


def _write(mesh, hole, top, folder, name):
    if not mesh.is_watertight or mesh.volume <= 0:
        return None  # a boolean that failed: draw again
    return write_mesh_body(mesh, hole, top, folder, name)


def ribbed_body(rng, peg, clearance, folder: Path, name: str):
    keep = keep_clear(peg, clearance)
    top = rng.uniform(0.05, 0.14)
    mesh, hole = _slab(rng, keep, top)
    for _ in range(int(rng.integers(1, 3))):
        mesh, top = add_ribs(rng, mesh, hole, top, keep)
    return _write(mesh, hole, top, folder, name)


def pocketed_body(rng, peg, clearance, folder: Path, name: str):
    keep = keep_clear(peg, clearance)
    top = rng.uniform(0.05, 0.14)
    mesh, hole = _slab(rng, keep, top)
    mesh, top = add_pockets(rng, mesh, hole, top, keep)
    if rng.random() < 0.6:
        mesh, top = add_counterbore(rng, mesh, hole, top, keep)
    return _write(mesh, hole, top, folder, name)


def narrow_body(rng, peg, clearance, folder: Path, name: str):
    """A bar just wider than the hole's wall, 8-26 cm tall, the hole anywhere along it."""
    keep = keep_clear(peg, clearance)
    top = rng.uniform(0.08, 0.26)
    width = 2 * keep + rng.uniform(0.0, 0.015)
    length = rng.uniform(max(2 * keep + 0.005, 0.09), 0.22)
    mesh = box_at([length, width, top], [0, 0, top / 2], 0.0)
    hole = np.array(
        [rng.uniform(-1, 1) * (length / 2 - keep), rng.uniform(-1, 1) * (width / 2 - keep)]
    )
    if rng.random() < 0.5:
        mesh, top = add_step(rng, mesh, hole, top, keep)
    return _write(mesh, hole, top, folder, name)


ELEMENTS = (add_ribs, add_pockets, add_counterbore, add_step)


def composite_body(rng, peg, clearance, folder: Path, name: str):
    """An L, T or U outline (boxes), the hole near an inner corner or an end, with two or
    three elements and a boss around the opening half the time."""
    keep = keep_clear(peg, clearance)
    top = rng.uniform(0.05, 0.2)
    arm = rng.uniform(2 * keep + 0.004, 2 * keep + 0.04)  # width of each arm
    span = rng.uniform(0.12, 0.24)
    shape = rng.choice(["L", "T", "U"])
    parts = [box_at([span, arm, top], [0, -span / 2 + arm / 2, top / 2])]  # the base arm
    if shape in ("L", "U"):
        parts.append(box_at([arm, span, top], [-span / 2 + arm / 2, 0, top / 2]))
    if shape == "U":
        parts.append(box_at([arm, span, top], [span / 2 - arm / 2, 0, top / 2]))
    if shape == "T":
        parts.append(box_at([arm, span, top], [0, 0, top / 2]))
    mesh = _union(parts)
    # The hole on an arm: its inner corner or its far end, within the arm's walls.
    corner = rng.random() < 0.5
    if shape == "T":
        y = -span / 2 + arm / 2 if corner else span / 2 - keep - 0.002
        hole = np.array([0.0 if not corner else rng.uniform(-1, 1) * (span / 2 - keep), y])
    else:
        x = -span / 2 + arm / 2
        hole = np.array([x, -span / 2 + arm / 2 if corner else span / 2 - keep - 0.002])
    hole = hole + rng.uniform(-1, 1, size=2) * max(0.0, arm / 2 - keep)
    for add in rng.choice(ELEMENTS, size=int(rng.integers(2, 4)), replace=False):
        mesh, top = add(rng, mesh, hole, top, keep)
    if rng.random() < 0.5:
        mesh, top = add_boss(rng, mesh, hole, top, keep)
    return _write(mesh, hole, top, folder, name)


def add_grooves(rng, mesh, hole, top, keep):
    """One to three grooves across the whole face beside the hole, each at its own angle:
    a 90 deg V (6-30 mm wide at the face) or a square slot (6-25 mm wide), 3-15 mm deep.
    A groove that crosses less than 2 cm of the face (its line beyond a narrow body's side,
    or clipping a corner) is drawn again."""
    wanted, cut = int(rng.integers(1, 4)), 0
    for _ in range(8 * wanted):
        side = rng.uniform(0, 2 * np.pi)
        depth = rng.uniform(0.003, min(0.015, 0.4 * top))
        vee = rng.random() < 0.5
        width = 2 * depth if vee else rng.uniform(0.006, 0.025)
        c = hole + _unit(side) * (keep + width / 2 + rng.uniform(0.002, 0.03))
        if vee:  # a square bar turned 45 deg about its length, its lower edge at the depth
            groove = trimesh.creation.box([0.04, 1.0, 0.04])
            groove.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 4, [0, 1, 0]))
            groove.apply_transform(trimesh.transformations.rotation_matrix(side, [0, 0, 1]))
            groove.apply_translation([*c, top - depth + 0.02 * np.sqrt(2)])
            section = depth * depth
        else:
            groove = box_at([width, 1.0, 2 * depth], [*c, top], side)
            section = width * depth
        cut_mesh = _minus(mesh, [groove])
        if cut_mesh.volume < mesh.volume - 0.02 * section:
            mesh, cut = cut_mesh, cut + 1
            if cut == wanted:
                break
    return mesh, top


def grooved_body(rng, peg, clearance, folder: Path, name: str):
    """A box or a disc, 5-14 cm tall, grooved across its face beside the hole; a
    counterbore round the opening a third of the time."""
    keep = keep_clear(peg, clearance)
    top = rng.uniform(0.05, 0.14)
    if rng.random() < 0.5:
        mesh, hole = _slab(rng, keep, top)
    else:
        r = rng.uniform(keep + 0.03, 0.11)
        mesh = trimesh.creation.cylinder(r, top, 96)
        mesh.apply_translation([0, 0, top / 2])
        hole = _unit(rng.uniform(0, 2 * np.pi)) * rng.uniform(0, r - keep)
    mesh, top = add_grooves(rng, mesh, hole, top, keep)
    if rng.random() < 1 / 3:
        mesh, top = add_counterbore(rng, mesh, hole, top, keep)
    return _write(mesh, hole, top, folder, name)


def add_wall(rng, mesh, hole, top, keep):
    """A wall or block standing on the face 1-4 cm from the opening's edge, 2-8 cm tall."""
    side = rng.uniform(0, 2 * np.pi)
    thick, length = rng.uniform(0.004, 0.03), rng.uniform(0.04, 0.2)
    h = rng.uniform(0.02, 0.08)
    c = hole + _unit(side) * (keep + rng.uniform(0.01, 0.04) + thick / 2)
    wall = box_at([thick, length, h + 0.002], [*c, top + h / 2 - 0.001], side)
    return _union([mesh, wall]), top


def add_drop(rng, mesh, hole, top, keep):
    """A step down, 1-4 cm from the opening's edge, to the table or part of the way."""
    return _step_down(rng, mesh, hole, top, keep, (0.01, 0.04), 0.4, 0.5)


def add_island(rng, mesh, hole, top, keep):
    """The opening on a small island: a round or square boss 1-5 mm wider than the
    opening's wall, 5-25 mm above the face."""
    return _raise_opening(rng, mesh, hole, top, keep, (0.005, 0.025), (0.001, 0.005))


def _raise_opening(rng, mesh, hole, top, keep, height, wider):
    """The opening on a round or square block `height` (m, range) above the face and
    `wider` (m, range) beyond the opening's wall: (mesh, the new face's height)."""
    h, r = rng.uniform(*height), keep + rng.uniform(*wider)
    if rng.random() < 0.5:
        block = trimesh.creation.cylinder(r, h + 0.002, 64)
        block.apply_translation([*hole, top + h / 2 - 0.001])
    else:
        block = box_at([2 * r, 2 * r, h + 0.002], [*hole, top + h / 2 - 0.001], rng.uniform(0, 1))
    return _union([mesh, block]), top + h


def add_decoys(rng, mesh, hole, top, keep):
    """One or two blind openings of other sizes (0.6-1.5 times the opening's half width),
    round or square, 1-3 cm deep, 1-6 cm from the opening's wall."""
    cuts = []
    half = keep - MIN_WALL
    for _ in range(int(rng.integers(1, 3))):
        r = half * rng.choice([rng.uniform(0.6, 0.85), rng.uniform(1.15, 1.5)])
        c = hole + _unit(rng.uniform(0, 2 * np.pi)) * (
            keep + r * np.sqrt(2) + rng.uniform(0.01, 0.06)
        )
        cuts.append(_blind_opening(rng, r, rng.uniform(0.01, 0.03), c, top))
    return _minus(mesh, cuts), top


def _blind_opening(rng, r: float, depth: float, centre, top: float) -> trimesh.Trimesh:
    """The cut of a blind opening `depth` deep into the face at `top`, at `centre` (x, y):
    round of radius `r`, or half the time square of half side `r` at a random turn."""
    if rng.random() < 0.5:
        cut = trimesh.creation.cylinder(r, 2 * depth, 64)
        cut.apply_translation([*centre, top])
        return cut
    return box_at([2 * r, 2 * r, 2 * depth], [*centre, top], rng.uniform(0, np.pi / 2))


PLATE_FEATURES = (add_wall, add_drop, add_island, add_decoys)


def plate_body(rng, peg, clearance, folder: Path, name: str):
    """A plate 18-30 cm wide, 5-8 cm thick, the opening far from its centre (40-100% of
    the way to the edge its wall allows), with one to three of: a wall or a step down 1-4
    cm from the opening, the opening on a small island, decoy openings of other sizes."""
    keep = keep_clear(peg, clearance)
    top = rng.uniform(0.05, 0.08)
    sx, sy = rng.uniform(0.18, 0.30), rng.uniform(0.12, 0.30)
    room = np.array([sx, sy]) / 2 - keep
    hole = room * rng.uniform(0.4, 1.0, size=2) * rng.choice([-1, 1], size=2)
    mesh = box_at([sx, sy, top], [0, 0, top / 2])
    for add in rng.choice(PLATE_FEATURES, size=int(rng.integers(1, 4)), replace=False):
        mesh, top = add(rng, mesh, hole, top, keep)
    return _write(mesh, hole, top, folder, name)


def add_bolt_circle(rng, mesh, hole, top, keep):
    """Four to eight drilled holes, 0.3-0.7 times the opening's half width, 1-2.5 cm deep,
    evenly on a circle round the opening 6-25 mm outside its wall (those on the face)."""
    half = keep - MIN_WALL
    r = half * rng.uniform(0.3, 0.7)
    ring = keep + r + rng.uniform(0.006, 0.025)
    n, turn, d = int(rng.integers(4, 9)), rng.uniform(0, 2 * np.pi), rng.uniform(0.01, 0.025)
    cuts = []
    for k in range(n):
        c = hole + _unit(turn + 2 * np.pi * k / n) * ring
        if not _solid_under(mesh, c, r, top):
            continue  # off the face's edge: a partial pattern, as near a real part's edge
        cut = trimesh.creation.cylinder(r, 2 * d, 32)
        cut.apply_translation([*c, top])
        cuts.append(cut)
    return _minus(mesh, cuts), top


def _solid_under(mesh: trimesh.Trimesh, centre, half: float, top: float) -> bool:
    """Whether the body fills the square of half side `half` round `centre` (x, y) in the
    millimetre below `top`: a footprint wholly on the face."""
    probe = box_at([2 * half, 2 * half, 0.001], [*centre, top - 0.0005])
    with np.errstate(invalid="ignore", divide="ignore"):  # an empty intersection's centre
        solid = trimesh.boolean.intersection([mesh, probe], engine="manifold").volume
    return solid > 0.99 * probe.volume


def add_pins(rng, mesh, hole, top, keep):
    """One to three dowel pins or posts (3-10 mm radius, 1.5-6 cm tall) standing 1-4 cm
    from the opening's wall."""
    pins, wanted = [], int(rng.integers(1, 4))
    for _ in range(8 * wanted):
        r, h = rng.uniform(0.003, 0.01), rng.uniform(0.015, 0.06)
        c = hole + _unit(rng.uniform(0, 2 * np.pi)) * (keep + r + rng.uniform(0.01, 0.04))
        if not _solid_under(mesh, c, r, top):
            continue  # a pin stands on the face, never beyond its edge or in a cut
        pin = trimesh.creation.cylinder(r, h + 0.002, 48)
        pin.apply_translation([*c, top + h / 2 - 0.001])
        pins.append(pin)
        if len(pins) == wanted:
            break
    return _union([mesh, *pins]), top


def add_ramp(rng, mesh, hole, top, keep):
    """A wedge beside the opening: its low edge 5-30 mm from the opening's wall, rising
    1-4 cm over 3-8 cm, 4-15 cm wide: a sloped face next to a flat one."""
    side = rng.uniform(0, 2 * np.pi)
    gap, run, rise = rng.uniform(0.005, 0.03), rng.uniform(0.03, 0.08), rng.uniform(0.01, 0.04)
    width = rng.uniform(0.04, 0.15)
    a, b = keep + gap, keep + gap + run  # along `side` from the hole
    z0, z1 = top - 0.001, top + rise
    ends = [(a, z0), (b, z0), (b, z1)]  # the wedge's section, extruded across its width
    u, v = _unit(side), _unit(side + np.pi / 2)
    corners = [[*(hole + u * x + v * w), z] for x, z in ends for w in (-width / 2, width / 2)]
    wedge = trimesh.convex.convex_hull(np.array(corners))
    return _union([mesh, wedge]), top


def _plate_or_disc(rng, keep: float, top: float, across: tuple[float, float]):
    """A plate (each side within `across`, m) or a disc (its diameter within it), `top`
    thick, and the opening's place anywhere on its face: (mesh, hole x y)."""
    if rng.random() < 0.5:
        sx, sy = rng.uniform(*across, size=2)
        mesh = box_at([sx, sy, top], [0, 0, top / 2])
        return mesh, (np.array([sx, sy]) / 2 - keep) * rng.uniform(-0.95, 0.95, size=2)
    r = rng.uniform(across[0] / 2, across[1] / 2)
    mesh = trimesh.creation.cylinder(r, top, 128)
    mesh.apply_translation([0, 0, top / 2])
    return mesh, _unit(rng.uniform(0, 2 * np.pi)) * (r - keep) * np.sqrt(rng.uniform(0, 0.9))


def _featured_part(
    rng, peg, clearance, folder, name, thick, across, features, last=(), base=_plate_or_disc
):
    """A `base` body (`_plate_or_disc`, `across` m) `thick` (m, range) thick with two or
    three of `features` added, those in `last` after the rest and in that order; None when
    a part is not joined to the body (it would float): draw again."""
    keep = keep_clear(peg, clearance)
    top = rng.uniform(*thick)
    mesh, hole = base(rng, keep, top, across)
    chosen = rng.choice(features, size=int(rng.integers(2, 4)), replace=False)
    for add in sorted(chosen, key=lambda f: last.index(f) + 1 if f in last else 0):
        mesh, top = add(rng, mesh, hole, top, keep)
    if len(mesh.split(only_watertight=False)) > 1:
        return None
    return _write(mesh, hole, top, folder, name)


def _part(thick, across, features, last=(), base=_plate_or_disc) -> Draw:
    """A family of `_featured_part` bodies: `thick` and `across` (m, ranges), two or three
    of `features`, those in `last` after the rest."""
    return partial(
        _featured_part, thick=thick, across=across, features=features, last=last, base=base
    )


FIXTURE_FEATURES = (add_bolt_circle, add_pins, add_ramp, add_wall, add_drop, add_island)


fixture_body = _part((0.03, 0.07), (0.12, 0.28), FIXTURE_FEATURES, last=(add_island,))
"""A fixture plate (12-28 cm) or a flange (a disc 12-28 cm across), 3-7 cm thick, the
opening anywhere on the face, with two or three of `FIXTURE_FEATURES` (an island last:
what stands beside the opening stands on the face, not at the island's height)."""


def add_countersink(rng, mesh, hole, top, keep):
    """The opening countersunk: a cone 60-90 deg across round its edge, 1-4 mm wider than
    the widest opening at the face; the opening (the frame) where the cone meets it."""
    bottom = keep - MIN_WALL  # the widest opening's circumscribed radius
    flare = rng.uniform(0.001, 0.004)
    depth = flare / np.tan(np.deg2rad(rng.uniform(30, 45)))  # half the cone's angle
    a = np.linspace(0, 2 * np.pi, 96, endpoint=False)
    rim = np.stack([np.cos(a), np.sin(a)], axis=1)
    lip = 0.001  # above the face, so the cut opens through it
    upper = np.c_[hole + rim * (bottom + flare * (1 + lip / depth)), np.full(96, top + lip)]
    lower = np.c_[hole + rim * bottom, np.full(96, top - depth)]
    cone = trimesh.convex.convex_hull(np.vstack([upper, lower]))
    return _minus(mesh, [cone]), top - depth


def add_tower(rng, mesh, hole, top, keep):
    """The opening on a round or square tower 4-12 cm above the face, 3-15 mm wider than
    the opening's wall: a small face far above the rest of the part."""
    return _raise_opening(rng, mesh, hole, top, keep, (0.04, 0.12), (0.003, 0.015))


def add_slot(rng, mesh, hole, top, keep):
    """An elongated blind slot 1-6 cm from the opening's wall: 0.8-1.3 times the opening's
    width across, 1.5-3 times as long as wide, 1-3 cm deep, rounded ends, its middle on
    the face."""
    w = (keep - MIN_WALL) / np.sqrt(2) * rng.uniform(0.8, 1.3)  # half the slot's width
    d = rng.uniform(0.01, 0.03)
    for _ in range(16):
        straight = 2 * w * rng.uniform(0.5, 2)
        side, turn = rng.uniform(0, 2 * np.pi), rng.uniform(0, np.pi)
        c = hole + _unit(side) * (keep + straight / 2 + w + rng.uniform(0.01, 0.06))
        if _solid_under(mesh, c, w, top):
            break
    else:
        return mesh, top  # no room on this face: the part goes without
    along = _unit(turn) * straight / 2
    ends = []
    for s in (-1, 1):
        end = trimesh.creation.cylinder(w, 2 * d, 48)
        end.apply_translation([*(c + s * along), top])
        ends.append(end)
    body = box_at([straight, 2 * w, 2 * d], [*c, top], turn)
    return _minus(mesh, [_union([body, *ends])]), top


def add_bracket(rng, mesh, hole, top, keep):
    """A bracket 1-4 cm from the opening's wall: a wall 3-8 cm tall braced on the opening's
    side by one to three gussets, sloped faces that rise from the face to the wall's top."""
    side = rng.uniform(0, 2 * np.pi)
    u, v = _unit(side), _unit(side + np.pi / 2)
    thick, length, h = rng.uniform(0.004, 0.012), rng.uniform(0.05, 0.16), rng.uniform(0.03, 0.08)
    gap = keep + rng.uniform(0.01, 0.04)
    run = min(gap - keep - 0.003, rng.uniform(0.01, 0.04))  # the gussets' foot, off the wall
    parts = [
        box_at(
            [thick, length, h + 0.002], [*(hole + u * (gap + thick / 2)), top + h / 2 - 0.001], side
        )
    ]
    for k in range(int(rng.integers(1, 4))):
        at = v * length * rng.uniform(-0.4, 0.4) if k else v * 0.0
        web = rng.uniform(0.002, 0.005) / 2
        section = [
            (gap + 0.001, top - 0.001),
            (gap - run, top - 0.001),
            (gap + 0.001, top + h * 0.8),
        ]
        corners = [[*(hole + u * x + at + v * w), z] for x, z in section for w in (-web, web)]
        parts.append(trimesh.convex.convex_hull(np.array(corners)))
    return _union([mesh, *parts]), top


HOUSING_FEATURES = (add_tower, add_slot, add_bracket, add_ribs, add_wall, add_countersink)


housing_body = _part(
    (0.03, 0.08), (0.10, 0.30), HOUSING_FEATURES, last=(add_tower, add_countersink)
)
"""A housing block (10-30 cm) or a disc 10-30 cm across, 3-8 cm thick, the opening
anywhere on the face, with two or three of `HOUSING_FEATURES` (a tower after what stands
on the face, a countersink last: it is cut where the opening ends up)."""


def _block_or_bar(rng, keep: float, top: float, across: tuple[float, float]):
    """A plate or disc (`_plate_or_disc`), or a third of the time a round bar with a flat
    milled along its top: a land 2-10 mm wider than the opening's wall each side, the bar's
    surface falling away round beyond it (radius 5-20 cm): (mesh, hole x y)."""
    if rng.random() < 2 / 3:
        return _plate_or_disc(rng, keep, top, across)
    length, width = rng.uniform(*across), rng.uniform(max(across[0], 4 * keep), across[1])
    radius = rng.uniform(max(0.05, top), 0.2)  # its lowest point under the table: a bar
    land = keep + rng.uniform(0.002, 0.01)  # half the flat's width
    hole = np.array([(length / 2 - keep) * rng.uniform(-0.9, 0.9), 0.0])
    hole[1] = (width / 2 - land) * rng.uniform(-0.8, 0.8)
    rise = radius - np.sqrt(radius**2 - land**2)  # the round's top above the land
    bar = trimesh.creation.cylinder(radius, length + 0.01, 128)
    bar.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    bar.apply_translation([0, hole[1], top + rise - radius])
    block = box_at([length, width, top], [0, 0, top / 2])
    return trimesh.boolean.intersection([block, bar], engine="manifold"), hole


def add_seal_groove(rng, mesh, hole, top, keep):
    """A face-seal (O-ring) groove round the opening: a ring 2-4 mm wide and 1.5-4 mm deep,
    its inner edge 2-8 mm outside the opening's wall."""
    inner = keep + rng.uniform(0.002, 0.008)
    width, depth = rng.uniform(0.002, 0.004), rng.uniform(0.0015, 0.004)
    ring = trimesh.creation.annulus(inner, inner + width, 2 * depth, sections=96)
    ring.apply_translation([*hole, top])
    return _minus(mesh, [ring]), top


def add_ports(rng, mesh, hole, top, keep):
    """One to three round ports wider than the opening (1.15-1.6 times its width), 1-4 cm
    deep, 1-5 cm from its wall, where the face holds them whole."""
    half = (keep - MIN_WALL) / np.sqrt(2)  # the opening's half width
    cuts = []
    for _ in range(int(rng.integers(1, 4))):
        r = half * rng.uniform(1.15, 1.6)
        c = hole + _unit(rng.uniform(0, 2 * np.pi)) * (keep + r + rng.uniform(0.01, 0.05))
        if not _solid_under(mesh, c, r, top):
            continue  # off the face's edge
        cut = trimesh.creation.cylinder(r, 2 * rng.uniform(0.01, 0.04), 64)
        cut.apply_translation([*c, top])
        cuts.append(cut)
    return _minus(mesh, cuts), top


def add_fittings(rng, mesh, hole, top, keep):
    """One or two hex fittings standing 1-4 cm from the opening's wall: 14-30 mm across
    the corners, 1-4 cm tall, each with a bore 0.3-0.6 times as wide down its middle (an
    opening above the face)."""
    fittings, wanted = [], int(rng.integers(1, 3))
    for _ in range(8 * wanted):
        r, h = rng.uniform(0.007, 0.015), rng.uniform(0.01, 0.04)
        c = hole + _unit(rng.uniform(0, 2 * np.pi)) * (keep + r + rng.uniform(0.01, 0.04))
        if not _solid_under(mesh, c, r / 2, top - 0.01):
            continue  # it stands on the part (a curved top included), not beyond its edge
        hexagon = trimesh.creation.cylinder(r, h + 0.012, 6)
        hexagon.apply_translation([*c, top + (h - 0.012) / 2])
        bore = trimesh.creation.cylinder(r * rng.uniform(0.3, 0.6), 2 * h, 32)
        bore.apply_translation([*c, top + h])
        fittings.append(_minus(hexagon, [bore]))
        if len(fittings) == wanted:
            break
    return _union([mesh, *fittings]), top


def add_offset_recess(rng, mesh, hole, top, keep):
    """The opening at one end of a long shallow recess with rounded ends, 2-6 mm deep, 2-8 mm
    wider than the opening's wall and running 2-6 cm the other way: the step close on one
    side of the opening, far on another."""
    r, d = keep + rng.uniform(0.002, 0.008), rng.uniform(0.002, 0.006)
    length, turn = rng.uniform(0.02, 0.06), rng.uniform(0, 2 * np.pi)
    far = hole + _unit(turn) * length
    ends = []
    for c in (hole, far):
        end = trimesh.creation.cylinder(r, 2 * d, 64)
        end.apply_translation([*c, top])
        ends.append(end)
    middle = box_at([length, 2 * r, 2 * d], [*(hole + far) / 2, top], turn)
    return _minus(mesh, [_union([middle, *ends])]), top - d


MANIFOLD_FEATURES = (add_ports, add_fittings, add_wall, add_offset_recess, add_seal_groove)


manifold_body = _part(
    (0.04, 0.10),
    (0.10, 0.30),
    MANIFOLD_FEATURES,
    last=(add_offset_recess, add_seal_groove),
    base=_block_or_bar,
)
"""A manifold block or disc (10-30 cm) or a round bar with a milled flat, 4-10 cm thick,
the opening anywhere on the face, with two or three of `MANIFOLD_FEATURES` (a recess
after what stands on the face, the seal groove last: both cut where the opening is)."""


def add_posts(rng, mesh, hole, top, keep):
    """One to three posts or blocks 1-13 cm tall and 1-6 cm across, 1-8 cm from the
    opening's wall, a third of them with a blind bore (0.6-1.5 times the opening's half
    width) in their top: tall things beside the opening that do not hold it."""
    half, parts, cuts = keep - MIN_WALL, [], []
    for _ in range(int(rng.integers(1, 4))):
        r, h = rng.uniform(0.005, 0.03), rng.uniform(0.01, 0.13)
        c = hole + _unit(rng.uniform(0, 2 * np.pi)) * (
            keep + r * np.sqrt(2) + rng.uniform(0.01, 0.08)
        )
        if rng.random() < 0.5:
            post = trimesh.creation.cylinder(r, h + 0.002, 48)
            post.apply_translation([*c, top + h / 2 - 0.001])
        else:
            post = box_at([2 * r, 2 * r, h + 0.002], [*c, top + h / 2 - 0.001], rng.uniform(0, 1))
        parts.append(post)
        bore = half * rng.choice([rng.uniform(0.6, 0.85), rng.uniform(1.15, 1.5)])
        if rng.random() < 1 / 3 and bore + MIN_WALL < r:
            cut = trimesh.creation.cylinder(bore, 2 * min(0.03, 0.8 * h), 48)
            cut.apply_translation([*c, top + h])
            cuts.append(cut)
    return _minus(_union([mesh, *parts]), cuts), top


STAND_FEATURES = (add_posts, add_wall, add_ribs, add_pockets, add_step)


def stand_body(rng, peg, clearance, folder: Path, name: str):
    """A plate or disc 8-30 cm across, 2-8 cm thick, the opening anywhere on it, with one to
    three of `STAND_FEATURES`, and three times in four the opening on a riser 1-13 cm tall
    (3-30 mm wider than its wall) put up after them."""
    keep = keep_clear(peg, clearance)
    top = rng.uniform(0.02, 0.08)
    mesh, hole = _plate_or_disc(rng, keep, top, (0.08, 0.30))
    for add in rng.choice(STAND_FEATURES, size=int(rng.integers(1, 4)), replace=False):
        mesh, top = add(rng, mesh, hole, top, keep)
    if rng.random() < 0.75:
        mesh, top = _raise_opening(rng, mesh, hole, top, keep, (0.01, 0.13), (0.003, 0.03))
    if len(mesh.split(only_watertight=False)) > 1:
        return None
    return _write(mesh, hole, top, folder, name)


def add_hub(rng, mesh, hole, top, keep):
    """The opening on a round hub 1-5 cm above the face, 3-12 mm wider than the opening's
    wall, braced by three to six gussets: webs 3-6 mm thick sloping from the face 1-4 cm
    out up to the hub's side, most of the way to its top."""
    h, r = rng.uniform(0.01, 0.05), keep + rng.uniform(0.003, 0.012)
    hub = trimesh.creation.cylinder(r, h + 0.002, 64)
    hub.apply_translation([*hole, top + h / 2 - 0.001])
    parts, n, turn = [hub], int(rng.integers(3, 7)), rng.uniform(0, 2 * np.pi)
    run, web = rng.uniform(0.01, 0.04), rng.uniform(0.003, 0.006) / 2
    for k in range(n):
        u = _unit(turn + 2 * np.pi * k / n)
        v = np.array([-u[1], u[0]])
        section = [(r - 0.002, top - 0.001), (r + run, top - 0.001), (r - 0.002, top + 0.8 * h)]
        corners = [[*(hole + u * x + v * w), z] for x, z in section for w in (-web, web)]
        parts.append(trimesh.convex.convex_hull(np.array(corners)))
    return _union([mesh, *parts]), top + h


def add_channel(rng, mesh, hole, top, keep):
    """The opening in a channel: two parallel walls 1-4 cm tall and 3-8 mm thick, each 5-25
    mm from the opening's wall, running 4-20 cm along it."""
    side, length, h = rng.uniform(0, np.pi), rng.uniform(0.04, 0.2), rng.uniform(0.01, 0.04)
    u = _unit(side)
    walls = []
    for s in (-1, 1):
        thick = rng.uniform(0.003, 0.008)
        c = hole + s * u * (keep + rng.uniform(0.005, 0.025) + thick / 2)
        walls.append(box_at([thick, length, h + 0.002], [*c, top + h / 2 - 0.001], side))
    return _union([mesh, *walls]), top


def add_bevel(rng, mesh, hole, top, keep):
    """A chamfered edge: 3-25 mm from the opening's wall the face falls away at 20-50 deg,
    5-30 mm down (at most 80% of the part's height), the rest of that side lower."""
    side, slope = rng.uniform(0, 2 * np.pi), np.deg2rad(rng.uniform(20, 50))
    gap, depth = keep + rng.uniform(0.003, 0.025), min(rng.uniform(0.005, 0.03), 0.8 * top)
    u, v = _unit(side), _unit(side + np.pi / 2)
    section = [(gap, top + 0.001), (1.0, top + 0.001), (1.0, top - depth)]
    section.append((gap + depth / np.tan(slope), top - depth))
    corners = [[*(hole + u * x + v * w), z] for x, z in section for w in (-0.5, 0.5)]
    return _minus(mesh, [trimesh.convex.convex_hull(np.array(corners))]), top


def add_raised_ring(rng, mesh, hole, top, keep):
    """A raised ring round the opening, as a flange's raised face or a cast lip: 2-5 mm
    wide, 1-3 mm tall, its inner edge 2-8 mm outside the opening's wall."""
    inner = keep + rng.uniform(0.002, 0.008)
    width, h = rng.uniform(0.002, 0.005), rng.uniform(0.001, 0.003)
    ring = trimesh.creation.annulus(inner, inner + width, h + 0.002, sections=96)
    ring.apply_translation([*hole, top + h / 2 - 0.001])
    return _union([mesh, ring]), top


def add_lightening(rng, mesh, hole, top, keep):
    """Lightening pockets: a row of two to five square pockets 1-3 cm wide and 5-20 mm deep
    (at most 60% of the part's height) between webs 3-6 mm thick, starting 5-30 mm from the
    opening's wall, where the face holds them whole."""
    side, w = rng.uniform(0, 2 * np.pi), rng.uniform(0.01, 0.03)
    web, d = rng.uniform(0.003, 0.006), min(rng.uniform(0.005, 0.02), 0.6 * top)
    start = keep + rng.uniform(0.005, 0.03) + w / 2
    cuts = []
    for k in range(int(rng.integers(2, 6))):
        c = hole + _unit(side) * (start + k * (w + web))
        if not _solid_under(mesh, c, w / 2, top):
            break  # the row ends at the face's edge
        cuts.append(box_at([w, w, 2 * d], [*c, top], side))
    return _minus(mesh, cuts), top


CASTING_FEATURES = (add_hub, add_channel, add_bevel, add_raised_ring, add_lightening)


casting_body = _part((0.03, 0.08), (0.10, 0.30), CASTING_FEATURES, last=(add_bevel, add_hub))
"""A cast plate or disc (10-30 cm), 3-8 cm thick, the opening anywhere on the face,
with two or three of `CASTING_FEATURES` (the bevel after what stands on the face, the
hub last: it stands where the opening is)."""


def add_other_openings(rng, mesh, hole, top, keep):
    """One to three blind openings the peg does not fit, round or square (either shape,
    whatever the peg's), 0.5-0.85 or 1.15-1.8 times the opening's half width, 1-4 cm deep,
    1-12 cm from its wall, where the face holds them whole."""
    half = (keep - MIN_WALL) / np.sqrt(2)  # the opening's half width
    cuts, wanted = [], int(rng.integers(1, 4))
    for _ in range(8 * wanted):
        r = half * (rng.uniform(0.5, 0.85) if rng.random() < 0.4 else rng.uniform(1.15, 1.8))
        reach = r * np.sqrt(2)  # a square one's corner
        c = hole + _unit(rng.uniform(0, 2 * np.pi)) * (keep + reach + rng.uniform(0.01, 0.12))
        if not _solid_under(mesh, c, reach, top):
            continue  # off the face's edge
        cuts.append(_blind_opening(rng, r, rng.uniform(0.01, 0.04), c, top))
        if len(cuts) == wanted:
            break
    return _minus(mesh, cuts), top


DECOY_COMPANIONS = (add_wall, add_step, add_pockets, add_ribs, add_counterbore)


def decoy_body(rng, peg, clearance, folder: Path, name: str):
    """A plate or disc 8-30 cm across, 2-10 cm thick, the opening anywhere on its face, with
    openings of other sizes and shapes (`add_other_openings`) and up to two of
    `DECOY_COMPANIONS` (a counterbore last: it lowers the face round the opening); None when
    no other opening fits or the body is not one piece."""
    keep = keep_clear(peg, clearance)
    top = rng.uniform(0.02, 0.10)
    plain, hole = _plate_or_disc(rng, keep, top, (0.08, 0.30))
    mesh, top = add_other_openings(rng, plain, hole, top, keep)
    if mesh.volume > plain.volume - 1e-7:
        return None  # no other opening fits on this face: draw again
    chosen = rng.choice(DECOY_COMPANIONS, size=int(rng.integers(0, 3)), replace=False)
    for add in sorted(chosen, key=lambda f: f is add_counterbore):
        mesh, top = add(rng, mesh, hole, top, keep)
    if len(mesh.split(only_watertight=False)) > 1:
        return None  # a step cut the part in two, or a rib stands off its edge: draw again
    return _write(mesh, hole, top, folder, name)


def _wheel(rng, keep: float, top: float, across: tuple[float, float]):
    """A wheel's disc (its diameter within `across`, m), `top` thick, the opening at its
    centre or, a third of the time (a crank, a cam), anywhere on its face: (mesh, hole x y)."""
    r = rng.uniform(across[0] / 2, across[1] / 2)
    mesh = trimesh.creation.cylinder(r, top, 128)
    mesh.apply_translation([0, 0, top / 2])
    if rng.random() < 2 / 3:
        return mesh, np.zeros(2)
    return mesh, _unit(rng.uniform(0, 2 * np.pi)) * (r - keep) * np.sqrt(rng.uniform(0, 0.8))


def _disc_radius(mesh: trimesh.Trimesh) -> float:
    """A wheel's radius (its disc stands centred on the origin)."""
    return float(mesh.bounds[1, 0])


def add_windows(rng, mesh, hole, top, keep):
    """Three to six round windows through the part, 6-20 mm in radius, evenly round the
    opening 5-30 mm outside its wall (those wholly on the face): the table seen through
    them, openings wider than the peg's with no floor."""
    r = rng.uniform(0.006, 0.02)
    ring = keep + r + rng.uniform(0.005, 0.03)
    n, turn = int(rng.integers(3, 7)), rng.uniform(0, 2 * np.pi)
    cuts = []
    for k in range(n):
        c = hole + _unit(turn + 2 * np.pi * k / n) * ring
        if _solid_under(mesh, c, r, top):
            cut = trimesh.creation.cylinder(r, 1.0, 48)
            cut.apply_translation([*c, 0.0])
            cuts.append(cut)
    return _minus(mesh, cuts), top


def add_spoked_web(rng, mesh, hole, top, keep):
    """The web round a hub recessed 5-15 mm (at most 60% of the part's height) between
    three to six spokes 5-15 mm wide left at the face's level: the opening on the hub, its
    face 4-20 mm wider than the opening's wall, the recess 2-6 cm wide beyond it."""
    hub = keep + rng.uniform(0.004, 0.02)
    outer = hub + rng.uniform(0.02, 0.06)
    d = min(rng.uniform(0.005, 0.015), 0.6 * top)
    recess = trimesh.creation.annulus(hub, outer, 2 * d, sections=96)
    recess.apply_translation([*hole, top])
    n, turn, w = int(rng.integers(3, 7)), rng.uniform(0, np.pi), rng.uniform(0.005, 0.015)
    spokes = []
    for k in range(n):
        a = turn + 2 * np.pi * k / n
        c = hole + _unit(a) * (hub + outer) / 2
        spokes.append(box_at([outer - hub + 0.004, w, 2 * d + 0.002], [*c, top], a))
    return _minus(mesh, [_minus(recess, spokes)]), top


def add_radial_ribs(rng, mesh, hole, top, keep):
    """Three to eight ribs 2-5 mm thick standing 5-20 mm above the face, radiating from
    3-10 mm outside the opening's wall out 2-8 cm (each standing on the part's floor, so it
    holds over a recess; near the wheel's edge it runs past it, down to the table)."""
    start, reach = keep + rng.uniform(0.003, 0.01), rng.uniform(0.02, 0.08)
    h, thick = rng.uniform(0.005, 0.02), rng.uniform(0.002, 0.005)
    n, turn = int(rng.integers(3, 9)), rng.uniform(0, np.pi)
    ribs = []
    for k in range(n):
        a = turn + 2 * np.pi * k / n
        c = hole + _unit(a) * (start + reach / 2)
        ribs.append(box_at([reach, thick, top + h], [*c, (top + h) / 2 + 0.0005], a))
    return _union([mesh, *ribs]), top


def add_outer_rim(rng, mesh, hole, top, keep):
    """A rim 4-12 mm wide standing 1-4 cm above the face round the wheel's edge, where it
    stays 2 cm or more from the opening's wall: the opening in a shallow bowl."""
    R = _disc_radius(mesh)
    width, h = rng.uniform(0.004, 0.012), rng.uniform(0.01, 0.04)
    if R - width - np.linalg.norm(hole) < keep + 0.02:
        return mesh, top  # too near the opening: the part goes without
    # 1 mm proud of the disc: a rim flush with its side leaves slivers where the two meet
    rim = trimesh.creation.annulus(R - width, R + 0.001, top + h, sections=128)
    rim.apply_translation([0, 0, (top + h) / 2 + 0.0005])
    return _union([mesh, rim]), top


def add_teeth(rng, mesh, hole, top, keep):
    """Gear teeth: 24-60 notches 2-6 mm deep round the wheel's edge, where they stay 1 cm
    or more from the opening's wall."""
    R = _disc_radius(mesh)
    depth = rng.uniform(0.002, 0.006)
    if R - depth - np.linalg.norm(hole) < keep + 0.01:
        return mesh, top
    n = int(rng.integers(24, 61))
    w = np.pi * R / n  # half the pitch: notches as wide as the teeth
    cuts = [
        box_at([2 * depth, w, 1.0], [*(_unit(a) * R), 0.0], a) for a in np.arange(n) * 2 * np.pi / n
    ]
    return _minus(mesh, [_union(cuts)]), top


WHEEL_FEATURES = (add_windows, add_spoked_web, add_radial_ribs, add_outer_rim, add_teeth)


wheel_body = _part(
    (0.02, 0.06),
    (0.10, 0.30),
    WHEEL_FEATURES,
    last=(add_windows, add_radial_ribs, add_outer_rim, add_teeth),
    base=_wheel,
)
"""A wheel, pulley or gear blank: a disc 10-30 cm across, 2-6 cm thick, the opening at its
centre (or, one in three, anywhere on the face), with two or three of `WHEEL_FEATURES`
(the spoked web first, the windows through what it leaves, the ribs, rim and teeth
standing on or cut from the rest)."""


def _solid(mesh: trimesh.Trimesh) -> mf.Manifold:
    return build._to_manifold(mesh.vertices, mesh.faces)


def _mesh(solid: mf.Manifold) -> trimesh.Trimesh:
    # simplified: no sliver an STL round trip would fold shut
    return trimesh.Trimesh(*build._from_manifold(solid.simplify(1e-6)))


def _extruded(region: mf.CrossSection, z0: float, z1: float) -> mf.Manifold:
    """`region` (a plan) as a solid from height `z0` to `z1` (m)."""
    return region.extrude(z1 - z0).translate([0.0, 0.0, z0])


def _cut(mesh: trimesh.Trimesh, region: mf.CrossSection, z0: float, z1: float):
    """`mesh` less `region` (a plan) between heights `z0` and `z1` (m)."""
    return _mesh(_solid(mesh) - _extruded(region, z0, z1))


def _plan(mesh: trimesh.Trimesh, z: float) -> mf.CrossSection:
    """The body's section at height `z` (m), as seen from above."""
    return _solid(mesh).slice(z)


def _disc(centre, r: float, sides: int = 64) -> mf.CrossSection:
    """A disc of radius `r` (m) at `centre` (x, y), as a polygon of `sides` sides."""
    return mf.CrossSection.circle(r, sides).translate(list(map(float, centre)))


def _inside(region: mf.CrossSection, points: np.ndarray) -> np.ndarray:
    """Which of `points` (N x 2) lie in `region` (even-odd over its contours)."""
    from matplotlib.path import Path as Outline  # only the families that cut plans need it

    count = np.zeros(len(points), int)
    for loop in region.to_polygons():
        count += Outline(np.asarray(loop)).contains_points(points)
    return count % 2 == 1


def _link(rng, keep: float, top: float, across: tuple[float, float]):
    """A link, lever or bellcrank: one to three arms 5-13 cm long from a pivot boss, each
    the hull of the pivot's disc and a smaller end disc; the opening at the pivot or, a
    third of the time, at an arm's end: (mesh, hole x y)."""
    pivot = keep + rng.uniform(0.005, 0.02)
    n = int(rng.choice([1, 2, 2, 3]))
    turns = rng.uniform(0, 2 * np.pi) + np.sort(rng.uniform(0, 2 * np.pi, n))
    while n > 1 and np.min(np.diff(np.r_[turns, turns[0] + 2 * np.pi])) < np.radians(50):
        turns = rng.uniform(0, 2 * np.pi) + np.sort(rng.uniform(0, 2 * np.pi, n))
    ends = []
    plan = _disc([0, 0], pivot)
    for a in turns:
        r_end = rng.uniform(max(keep + 0.003, 0.6 * pivot), pivot)
        ends.append(_unit(a) * rng.uniform(*across))
        plan = plan + mf.CrossSection.batch_hull([_disc([0, 0], pivot), _disc(ends[-1], r_end)])
    mesh = _mesh(_extruded(plan, 0.0, top))
    return mesh, (np.zeros(2) if rng.random() < 2 / 3 else ends[int(rng.integers(n))])


def add_i_section(rng, mesh, hole, top, keep):
    """The arms' web recessed 3-12 mm (at most half the part's height) inside flanges 3-8
    mm wide along the outline, up to a ring 4-15 mm wide left round the opening: an I-beam's
    section, the opening's face a narrow ring between recesses."""
    d, flange = min(rng.uniform(0.003, 0.012), 0.5 * top), rng.uniform(0.003, 0.008)
    web = _plan(mesh, top - 0.0005).offset(-flange, mf.JoinType.Round)
    web = web - _disc(hole, keep + rng.uniform(0.004, 0.015))
    return _cut(mesh, web, top - d, top + 0.01), top


def add_knurl(rng, mesh, hole, top, keep):
    """A knurled or diamond-plate pad: two sets of grooves 0.5-1.5 mm deep, 1-2.5 mm wide,
    5-10 mm apart, crossing at 60-90 deg, on the face from 2-8 mm outside the opening's
    wall out to 3-8 cm from it: many small edges round the opening."""
    d, w, pitch = rng.uniform(0.0005, 0.0015), rng.uniform(0.001, 0.0025), rng.uniform(0.005, 0.01)
    reach = keep + rng.uniform(0.03, 0.08)
    first = rng.uniform(0, np.pi)
    grooves = []
    for a in (first, first + rng.uniform(np.pi / 3, np.pi / 2)):
        for s in np.arange(-reach, reach, pitch):
            bar = mf.CrossSection.square([2 * reach, w], center=True).translate([0.0, s])
            grooves.append(bar.rotate(float(np.degrees(a))).translate(list(map(float, hole))))
    pad = _disc(hole, reach) - _disc(hole, keep + rng.uniform(0.002, 0.008))
    cut = mf.CrossSection.batch_boolean(grooves, mf.OpType.Add) ^ pad
    return _cut(mesh, cut, top - d, top + 0.01), top


def add_radial_slot(rng, mesh, hole, top, keep):
    """An adjusting slot through the part: 6-14 mm wide, 2-6 cm long, pointing at the
    opening from 5-20 mm outside its wall, with a wall 3-8 mm round it (the table seen
    through it, a long straight edge aimed at the opening)."""
    plan = _plan(mesh, 0.0005)
    w, length = rng.uniform(0.006, 0.014), rng.uniform(0.02, 0.06)
    gap, edge = rng.uniform(0.005, 0.02), rng.uniform(0.003, 0.008)
    for a in rng.uniform(0, 360, 60):  # a direction along which the part has room
        ends = [_disc([keep + gap + w / 2 + t, 0.0], w / 2, 32) for t in (0.0, length)]
        slot = mf.CrossSection.batch_hull(ends).rotate(a).translate(list(map(float, hole)))
        if (slot.offset(edge, mf.JoinType.Round) - plan).is_empty():
            return _cut(mesh, slot, -0.01, top + 0.01), top
    return mesh, top


def add_far_bores(rng, mesh, hole, top, keep):
    """One or two bores through the part (round or square, half to twice the opening's
    width, narrower where the part is) 4 cm or more from it with a wall 3-10 mm round them:
    a link's other ends."""
    half = keep - MIN_WALL
    footprint = _plan(mesh, 0.0005)
    (x0, y0), (x1, y1) = mesh.bounds[0, :2], mesh.bounds[1, :2]
    cuts = []
    for _ in range(int(rng.integers(1, 3))):
        widest = half * rng.uniform(0.5, 2)
        square, edge = rng.random() < 0.4, rng.uniform(0.003, 0.01)
        for r in [s for s in widest * 0.8 ** np.arange(8) if s >= 0.5 * half]:  # one with room
            wall = r * (np.sqrt(2) if square else 1.0) + edge
            room = footprint.offset(-wall, mf.JoinType.Round) - _disc(hole, keep + 0.04)
            for cut in cuts:
                room = room - cut.offset(wall, mf.JoinType.Round)
            seen = np.c_[rng.uniform(x0, x1, 400), rng.uniform(y0, y1, 400)]
            seen = seen[_inside(room, seen)]
            if len(seen):
                break
        else:
            continue
        bore = mf.CrossSection.square([2 * r, 2 * r], center=True).rotate(rng.uniform(0, 90))
        cuts.append((bore if square else _disc([0, 0], r)).translate(list(map(float, seen[0]))))
    if not cuts:
        return mesh, top
    return _cut(mesh, mf.CrossSection.batch_boolean(cuts, mf.OpType.Add), -0.01, top + 0.01), top


LINK_FEATURES = (add_i_section, add_knurl, add_radial_slot, add_far_bores, add_boss)


link_body = _part(
    (0.05, 0.075),
    (0.05, 0.13),
    LINK_FEATURES,
    last=(add_knurl, add_radial_slot, add_far_bores, add_boss),
    base=_link,
)
"""A link, lever or bellcrank 5-7.5 cm thick (the opening's 48 mm need it), up to 30 cm
across (arms 5-13 cm long), the opening at the pivot or an arm's end, with two or three of
`LINK_FEATURES` (the I-section first; the knurl, the slot and the far bores cut what it
leaves; a boss on top last)."""


FAMILIES: dict[str, Draw] = {
    "ribs": ribbed_body,
    "pockets": pocketed_body,
    "narrow": narrow_body,
    "composite": composite_body,
    "grooved": grooved_body,
    "plates": plate_body,
    "fixtures": fixture_body,
    "housings": housing_body,
    "manifolds": manifold_body,
    "stands": stand_body,
    "castings": casting_body,
    "decoys": decoy_body,
    "wheels": wheel_body,
    "links": link_body,
}
HELD_OUT_FAMILIES = (
    *("composite", "grooved", "plates", "fixtures", "housings", "manifolds", "castings"),
    *("wheels", "links"),
)
"""Never drawn for training: the frozen generalisation sets' families."""
