"""Turn a HoleSpec into simulation geometry: body mesh, hole cut, convex collision parts.

Frames (metres): the body frame has its origin at the centre of the body's bounding box in x
and y and at its bottom in z, so the body rests on z = 0. The *hole frame* sits at the
centre of the hole's opening on the top face, axes parallel to the body's: +z points out of
the hole, the bottom of the hole is at z = -depth. The square hole's sides are parallel to
the body's x and y axes.

The hole is cut with manifold3d (exact, watertight booleans). The collision shape is a
convex decomposition of the cut body in wedges around the hole (`convex_decomposition`):
no part reaches into the hole and its wall has no seam between its floor and its opening;
both are cached on disk under a hash of everything that changes the geometry, so a cached load
takes milliseconds.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import logging
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import manifold3d as mf
import numpy as np
import trimesh

from cfvs_maniskill import resources
from cfvs_maniskill.constants import (
    DEFAULT_CLEARANCE,
    DEFAULT_HOLE_DEPTH,
    MIN_FLOOR,
    MIN_WALL,
    PEG_LENGTH,
    hole_half_extent,
)
from cfvs_maniskill.objects.spec import HoleSpec, HoleSpecError

log = logging.getLogger(__name__)

BUILD_VERSION = 4
"""Bump when the geometry code changes, so stale cache entries are not reused."""
CYLINDER_SEGMENTS = 96
"""Facets of round bodies and round holes: 1.6 um chord error on a 25 mm hole."""
COACD_THRESHOLDS = (0.04, 0.02, 0.01)
MAX_BODY_FACES = 50_000
"""Mesh bodies with more triangles are simplified first (CoACD and the wrist camera's
frame time grow with the triangle count; a scanned part can have millions)."""
SIMPLIFY_TOLERANCE = 0.0002
"""Largest surface deviation (m) the simplification may make: 0.2 mm, far below the
clearance; the hole itself is cut afterwards, exactly."""
"""Concavity thresholds tried in turn until no convex part reaches into the hole."""
HOLE_CHECK_SHRINK = 0.001
"""A part may not overlap the hole volume shrunk by this much (1 mm) on every side."""
FACE_TOLERANCE = 0.001
"""hole_frame.origin may sit this far (1 mm) off its face along the axis (CAD coordinates
rounded by hand); the opening is put on the face itself."""


def cache_dir() -> Path:
    return resources.cache_root() / "holes"


@dataclass
class HoleGeometry:
    """Everything the simulator needs for one (spec, peg profile, clearance, depth)."""

    name: str
    profile: str
    clearance: float
    depth: float
    visual_vertices: np.ndarray  # (V, 3) float32, body frame, metres
    visual_faces: np.ndarray  # (F, 3) int32
    collision_parts: list[tuple[np.ndarray, np.ndarray]]  # convex (vertices, faces) pairs
    hole_frame: np.ndarray  # (3,) position of the hole frame's origin in the body frame
    body_height: float
    cache_key: str

    @property
    def hole_half_extent(self) -> float:
        return hole_half_extent(self.profile, self.clearance)

    def visual_trimesh(self) -> trimesh.Trimesh:
        return trimesh.Trimesh(self.visual_vertices, self.visual_faces, process=False)

    def mesh_files(self) -> tuple[Path, list[Path]]:
        """OBJ files (visual, convex parts) for SAPIEN's loaders, written once per cache key.

        Safe with any number of processes at once: each writes its own temporary folder
        and publishes it with one atomic rename; the first to publish wins and the others
        use its folder. A complete folder is never deleted, and a reader never sees a
        partial one (it only uses a folder whose files are all there).
        """
        d = cache_dir() / self.cache_key
        visual = d / "visual.obj"
        parts = [d / f"part{i:03d}.obj" for i in range(len(self.collision_parts))]
        files = [visual, *parts]
        if all(p.is_file() for p in files):
            return visual, parts
        d.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(dir=d.parent, prefix=".tmp"))
        try:
            self.visual_trimesh().export(tmp / visual.name)
            for (v, f), p in zip(self.collision_parts, parts, strict=True):
                trimesh.Trimesh(v, f, process=False).export(tmp / p.name)
            if not _publish_dir(tmp, d) and not all(p.is_file() for p in files):
                # Only a damaged folder (files removed by hand) gets here: move it aside
                # atomically (one process wins), then publish ours.
                aside = Path(tempfile.mkdtemp(dir=d.parent, prefix=".old"))
                with contextlib.suppress(OSError):
                    os.rename(d, aside / "entry")
                _publish_dir(tmp, d)
                shutil.rmtree(aside, ignore_errors=True)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)  # ours, unless it was published
        if not all(p.is_file() for p in files):
            missing = [str(p) for p in files if not p.is_file()]
            raise RuntimeError(f"hole cache entry {d} is incomplete: missing {missing}")
        return visual, parts


def _publish_dir(tmp: Path, d: Path) -> bool:
    """Rename tmp to d in one step; False when d already exists (someone else's entry)."""
    try:
        os.rename(tmp, d)  # atomic; fails on an existing non-empty folder
        return True
    except OSError as e:
        if e.errno in (errno.EEXIST, errno.ENOTEMPTY):
            return False
        raise


# --------------------------------------------------------------------------------------------
# manifold helpers
# --------------------------------------------------------------------------------------------


def _to_manifold(vertices: np.ndarray, faces: np.ndarray) -> mf.Manifold:
    mesh = mf.Mesh(
        vert_properties=np.ascontiguousarray(vertices, dtype=np.float32),
        tri_verts=np.ascontiguousarray(faces, dtype=np.uint32),
    )
    return mf.Manifold(mesh)


def _from_manifold(m: mf.Manifold) -> tuple[np.ndarray, np.ndarray]:
    mesh = m.to_mesh()
    return (
        np.asarray(mesh.vert_properties, dtype=np.float32)[:, :3].copy(),
        np.asarray(mesh.tri_verts, dtype=np.int32).copy(),
    )


def hole_solid(profile: str, half: float, z0: float, z1: float, at: tuple[float, float]):
    """The hole's volume (a square box or a cylinder) from z0 to z1 at (x, y) = at."""
    h = z1 - z0
    if half <= 0 or h <= 0:
        return mf.Manifold()
    if profile == "square":
        s = mf.Manifold.cube([2 * half, 2 * half, h], True)
    else:
        s = mf.Manifold.cylinder(h, half, half, CYLINDER_SEGMENTS, True)
    return s.translate([at[0], at[1], (z0 + z1) / 2])


# --------------------------------------------------------------------------------------------
# body
# --------------------------------------------------------------------------------------------


def _body_field(spec: HoleSpec) -> str:
    return {
        "box": "body.box.size",
        "cylinder": "body.cylinder",
        "prism": "body.prism",
        "mesh": "body.mesh.file",
    }[spec.body_kind]


def _load_mesh_body(spec: HoleSpec) -> mf.Manifold:
    path = spec.mesh_file
    fld = "body.mesh.file"
    try:
        loaded = trimesh.load(path, force="mesh", process=True)
    except Exception as e:  # trimesh raises many types for bad files
        raise HoleSpecError(spec.source, fld, f"cannot read mesh {path}: {e}") from e
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise HoleSpecError(spec.source, fld, f"mesh {path} has no triangles")
    mesh = loaded
    mesh.apply_scale(spec.body["scale"])
    if not mesh.is_watertight:
        raise HoleSpecError(
            spec.source,
            fld,
            f"mesh {path} is not watertight (it has open edges), so it has no inside to cut "
            "the hole from; expected a closed surface",
        )
    if mesh.volume <= 1e-9:
        raise HoleSpecError(
            spec.source, fld, f"mesh {path} is degenerate (volume {mesh.volume:.3g} m^3)"
        )
    if not mesh.is_volume:
        mesh.fix_normals()
    m = _to_manifold(mesh.vertices, mesh.faces)
    if m.status() != mf.Error.NoError or m.is_empty():
        raise HoleSpecError(
            spec.source, fld, f"mesh {path} is not a valid closed 2-manifold ({m.status()})"
        )
    if m.num_tri() > MAX_BODY_FACES:
        simple = m.simplify(SIMPLIFY_TOLERANCE)
        log.warning(
            "%s: %s: mesh %s has %d triangles (> %d); simplified to %d within %.1f mm for "
            "collision and rendering (the result is cached)",
            spec.source, fld, path, m.num_tri(), MAX_BODY_FACES, simple.num_tri(),
            1000 * SIMPLIFY_TOLERANCE,
        )  # fmt: skip
        m = simple
    return m


def body_solid(spec: HoleSpec) -> mf.Manifold:
    """The body without the hole in its own frame: primitives in the body frame (bottom at
    z = 0, centred in x, y), a mesh in its file's coordinates (scaled to metres)."""
    b = spec.body
    if spec.body_kind == "box":
        sx, sy, sz = b["size"]
        return mf.Manifold.cube([sx, sy, sz], True).translate([0, 0, sz / 2])
    if spec.body_kind == "cylinder":
        return mf.Manifold.cylinder(b["height"], b["radius"], b["radius"], CYLINDER_SEGMENTS)
    if spec.body_kind == "prism":
        # Regular polygon with circumradius `radius`; rotated so that one side faces +x.
        p = mf.Manifold.cylinder(b["height"], b["radius"], b["radius"], b["sides"])
        v = np.asarray(p.to_mesh().vert_properties)[:, :2]
        ang0 = np.arctan2(v[:, 1], v[:, 0]).min()
        return p.rotate([0, 0, float(np.degrees(np.pi / b["sides"] - ang0))])
    return _load_mesh_body(spec)


def _rotation_to_z(axis: np.ndarray) -> np.ndarray:
    """The shortest rotation turning unit vector `axis` onto +z."""
    c = float(axis[2])
    if c < -1 + 1e-12:  # straight down: half a turn about x
        return np.diag([1.0, -1.0, -1.0])
    v = np.cross(axis, [0.0, 0.0, 1.0])
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + K @ K / (1 + c)


def oriented_body(spec: HoleSpec) -> tuple[mf.Manifold, tuple[float, float], float | None]:
    """The body in the body frame (hole axis +z, bottom at z = 0, centred in x, y), where
    the hole opens in x, y, and the opening's height when `hole_frame` gives it (None: the
    top face over that point)."""
    body = body_solid(spec)
    at: tuple[float, float] = spec.hole_at
    origin = None
    if spec.hole_frame is not None:
        o, axis = spec.hole_frame
        R = _rotation_to_z(np.asarray(axis, np.float64))
        body = body.transform(np.hstack([R, np.zeros((3, 1))]))
        scale = spec.body["scale"] if spec.body_kind == "mesh" else 1.0
        origin = R @ (np.asarray(o, np.float64) * scale)
    bb = body.bounding_box()
    shift = np.array([-(bb[0] + bb[3]) / 2, -(bb[1] + bb[4]) / 2, -bb[2]])
    body = body.translate(shift.tolist())
    if origin is None:
        return body, at, None
    origin = origin + shift
    return body, (float(origin[0]), float(origin[1])), float(origin[2])


def _surface_crossings(body: mf.Manifold, at: tuple[float, float]) -> np.ndarray:
    """Heights where the vertical line through `at` crosses the body's surface, top first:
    from above, the 1st, 3rd, ... enter the body and the 2nd, 4th, ... leave it."""
    v, f = _from_manifold(body)
    tri = v[f].astype(np.float64)  # (F, 3, 3)
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    # Barycentric coordinates of (x, y) in each triangle's projection on the xy plane.
    d = (b[:, 1] - c[:, 1]) * (a[:, 0] - c[:, 0]) + (c[:, 0] - b[:, 0]) * (a[:, 1] - c[:, 1])
    ok = np.abs(d) > 1e-15
    d = np.where(ok, d, 1.0)
    px, py = at
    l1 = ((b[:, 1] - c[:, 1]) * (px - c[:, 0]) + (c[:, 0] - b[:, 0]) * (py - c[:, 1])) / d
    l2 = ((c[:, 1] - a[:, 1]) * (px - c[:, 0]) + (a[:, 0] - c[:, 0]) * (py - c[:, 1])) / d
    l3 = 1 - l1 - l2
    eps = -1e-9
    hit = ok & (l1 >= eps) & (l2 >= eps) & (l3 >= eps)
    return np.unique(np.round((l1 * a[:, 2] + l2 * b[:, 2] + l3 * c[:, 2])[hit], 7))[::-1]


def _contained(body: mf.Manifold, solid: mf.Manifold) -> bool:
    vol = solid.volume()
    return vol > 0 and (solid ^ body).volume() >= vol * (1 - 1e-6)


def check_room(
    spec: HoleSpec,
    body: mf.Manifold,
    profile: str,
    clearance: float,
    depth: float,
    at: tuple[float, float] | None = None,
    z_open: float | None = None,
):
    """Raise HoleSpecError unless the body can host the hole; returns the hole-frame origin.

    `at`, `z_open`: where the hole opens (body frame; from `oriented_body`). Without z_open
    the hole opens on the body's top surface over `at` (the `hole_at` contract).
    """
    fld = _body_field(spec)
    at = spec.hole_at if at is None else at
    where = "hole_frame.origin" if spec.hole_frame is not None else "hole_at"
    shown = list(spec.hole_frame[0]) if spec.hole_frame is not None else list(at)
    zs = _surface_crossings(body, at)
    if len(zs) < 2:
        raise HoleSpecError(
            spec.source,
            where,
            f"{shown} is not over the body's {'face' if z_open is not None else 'top face'}; "
            "expected a point within the body's footprint"
            + (" along hole_frame.axis" if z_open is not None else " (metres from its centre)"),
        )
    i = 0
    if z_open is not None:
        i = int(np.argmin(np.abs(zs - z_open)))
        off = abs(zs[i] - z_open)
        if off > FACE_TOLERANCE:
            raise HoleSpecError(
                spec.source,
                where,
                f"{shown} is {1000 * off:.1f} mm from the nearest surface of the body along "
                f"hole_frame.axis; expected a point on the face the hole opens on (within "
                f"{1000 * FACE_TOLERANCE:.0f} mm)",
            )
        if i % 2 == 1 or i + 1 >= len(zs):
            raise HoleSpecError(
                spec.source,
                "hole_frame.axis",
                f"points into the part at {shown}: the face there has material above it; "
                "expected the face's outward normal",
            )
    z_top, z_exit = float(zs[i]), float(zs[i + 1])
    half = hole_half_extent(profile, clearance)
    # The peg comes in along the axis: nothing of the body may sit over the opening.
    approach = hole_solid(profile, half - HOLE_CHECK_SHRINK, z_top + 1e-4, z_top + PEG_LENGTH, at)
    over = approach.volume() - (approach - body).volume()
    if over > 1e-9:
        raise HoleSpecError(
            spec.source,
            where,
            f"the body reaches over the opening at {shown}: {1e6 * over:.1f} cm^3 of it within "
            f"{1000 * PEG_LENGTH:.0f} mm above the hole, where the peg comes in; expected a "
            "clear approach along the hole's axis",
        )
    need = depth + MIN_FLOOR
    if z_top - z_exit < need - 1e-9:
        raise HoleSpecError(
            spec.source,
            fld,
            f"body is {1000 * (z_top - z_exit):.1f} mm thick under the hole but the hole needs "
            f"{1000 * depth:.1f} mm depth + {1000 * MIN_FLOOR:.1f} mm floor: "
            f"{1000 * (need - (z_top - z_exit)):.1f} mm missing (hole deeper than the body)",
        )

    def fits(margin: float) -> bool:
        return _contained(
            body, hole_solid(profile, half + margin, z_top - depth - MIN_FLOOR, z_top - 1e-4, at)
        )

    if not fits(MIN_WALL):
        lo, hi = -half, MIN_WALL  # bisection for the widest wall the body leaves
        for _ in range(16):
            mid = (lo + hi) / 2
            lo, hi = (mid, hi) if fits(mid) else (lo, mid)
        wall = lo
        width = 2 * (half + MIN_WALL)
        raise HoleSpecError(
            spec.source,
            fld,
            f"body too small for the {profile} hole ({1000 * 2 * half:.1f} mm wide) at {where} "
            f"{shown}: it needs {1000 * width:.1f} mm of flat face (a {1000 * MIN_WALL:.1f} mm "
            f"wall all round) but leaves a wall of {1000 * max(wall, 0):.1f} mm: "
            f"{1000 * (MIN_WALL - wall):.1f} mm missing",
        )
    return np.array([at[0], at[1], z_top])


# --------------------------------------------------------------------------------------------
# collision
# --------------------------------------------------------------------------------------------


def parts_in_hole(parts, hole_origin, profile, half, depth) -> list[int]:
    """Indices of convex parts that overlap the hole volume shrunk by HOLE_CHECK_SHRINK."""
    probe = hole_solid(
        profile,
        half - HOLE_CHECK_SHRINK,
        hole_origin[2] - depth + HOLE_CHECK_SHRINK,
        hole_origin[2] + PEG_LENGTH,  # also nothing above the opening
        (hole_origin[0], hole_origin[1]),
    )
    bad = []
    for i, (v, _) in enumerate(parts):
        hull = mf.Manifold.hull_points(np.asarray(v, dtype=np.float32))
        if (hull ^ probe).volume() > 1e-9:
            bad.append(i)
    return bad


def hole_sectors(profile: str, half: float, clearance: float) -> np.ndarray:
    """Angles (radians) of the planes through the hole axis that cut the body into wedges.

    Square hole: the four diagonals, so each wedge holds one flat hole wall and is convex
    where the hole is. Round hole: enough wedges that the chord of each wedge's arc sits at
    most min(0.5 mm, clearance / 8) inside the hole wall, so the hull of a wedge cannot
    shrink the hole by more than that.
    """
    if profile == "square":
        return np.pi / 4 + np.arange(4) * np.pi / 2
    sagitta = min(0.0005, clearance / 8)
    n = int(np.ceil(np.pi / np.arccos(1 - sagitta / half)))
    return np.arange(max(n, 8)) * 2 * np.pi / max(n, 8)


def _pieces(cut: mf.Manifold, origin: np.ndarray, depth: float, angles: np.ndarray):
    """The floor slab under the hole, and the body around the hole cut into wedges: yields
    (piece, outward unit vector of the wedge's middle in x y), the vector None for the slab."""
    # Split 10 um above the hole's floor: a split exactly at the floor leaves zero-thickness
    # slivers of it in the wedges, whose hulls would then reach the hole's axis.
    z_bottom = float(origin[2] - depth) + 1e-5
    upper = cut.trim_by_plane([0, 0, 1], z_bottom)
    yield cut.trim_by_plane([0, 0, -1], -z_bottom), None
    c = origin[:2]
    for a, b in zip(angles, np.roll(angles, -1), strict=True):
        n_a = np.array([-np.sin(a), np.cos(a)])  # keeps the side counter-clockwise of ray a
        n_b = np.array([np.sin(b), -np.cos(b)])  # keeps the side clockwise of ray b
        w = upper.trim_by_plane([*n_a, 0], float(n_a @ c)).trim_by_plane([*n_b, 0], float(n_b @ c))
        mid = a + ((b - a) % (2 * np.pi)) / 2
        yield w, np.array([np.cos(mid), np.sin(mid)])


def lining_depth(profile: str, half: float, angles: np.ndarray) -> float:
    """How far from the hole's axis, along a wedge's middle, its lining ends: MIN_WALL
    outside the wall, where check_room guarantees solid material all round (for a round
    hole, the plane that stays inside the hole grown by MIN_WALL across the wedge)."""
    if profile == "square":
        return half + MIN_WALL
    return (half + MIN_WALL) * float(np.cos(np.pi / len(angles)))


def _split_lining(piece: mf.Manifold, origin, outward: np.ndarray, reach: float):
    """A wedge as (lining, rest): the part within `reach` of the hole's axis along the wedge's
    middle (the hole wall and the material just behind it), and the part beyond."""
    n = np.array([*outward, 0.0])
    d = float(n[:2] @ origin[:2]) + reach
    return piece.trim_by_plane((-n).tolist(), -d), piece.trim_by_plane(n.tolist(), d)


def convex_decomposition(cut: mf.Manifold, origin, profile, half, clearance, depth, source: Path):
    """Convex parts of the cut body: every hull kept out of the hole, its walls seamless.

    Plain CoACD on a whole body with a round hole took 60-130 s and gave 200-400 parts (its
    concavity threshold cannot tell a hole wall from the rest). Cut into wedges, a primitive
    body needs no CoACD at all (each wedge is its own hull) and a mesh body is fast.

    A concave wedge (a boss on a plate, a step) is first split into its lining, the wall and
    MIN_WALL of material behind it over the hole's whole depth, which is one convex part,
    and the rest, which CoACD decomposes. Given the whole wedge, CoACD cut the wall where the
    boss met the plate; a peg sliding down a 0.25 mm gap caught its lower edge on the
    lower part's top edge there (PhysX's internal-edge contacts): at 0.5 mm clearance 14 of
    40 CFVS episodes on a boss plate and a chamfered hub stopped 1.7 mm (the peg's chamfer)
    below that seam, 13 of 20 on a stepped boss below one of its two seams.
    """
    import coacd

    coacd.set_log_level("error")
    angles = hole_sectors(profile, half, clearance)
    reach = lining_depth(profile, half, angles)
    column = hole_solid(profile, half, origin[2] - depth - 1.0, origin[2] + 1.0, origin[:2])
    parts: list[tuple[np.ndarray, np.ndarray]] = []
    for piece, outward in _pieces(cut, origin, depth, angles):
        if _empty(piece):
            continue
        hull = _hull_if_convex(piece)
        if hull is not None and not parts_in_hole([hull], origin, profile, half, depth):
            parts.append(hull)
            continue
        rest = [piece]
        if outward is not None:
            lining, beyond = _split_lining(piece, origin, outward, reach)
            lined = _hull_if_convex(lining, allowed=column)
            if lined is not None and not parts_in_hole([lined], origin, profile, half, depth):
                parts.append(lined)
                rest = [] if _empty(beyond) else [beyond]
        for p in rest:
            parts += _coacd_parts(p, origin, profile, half, depth, source, coacd)
    return parts


def _empty(piece: mf.Manifold) -> bool:
    return piece.is_empty() or piece.volume() < 1e-10


def _hull_if_convex(piece: mf.Manifold, allowed: mf.Manifold | None = None):
    """The piece's hull as (vertices, faces) if it adds under 1% to the piece's volume
    (outside `allowed`: the hole, where a round wall's facets leave their sagitta), else
    None. A wedge of a convex body is convex up to the arc of the hole wall."""
    if _empty(piece):
        return None
    hull = piece.hull()
    added = (
        hull.volume() - piece.volume() if allowed is None else ((hull - piece) - allowed).volume()
    )
    return _from_manifold(hull) if added <= 0.01 * piece.volume() else None


def _coacd_parts(piece: mf.Manifold, origin, profile, half, depth, source: Path, coacd):
    """CoACD's parts of a concave piece, at the first threshold that keeps them out of the
    hole."""
    v, f = _from_manifold(piece)
    mesh = coacd.Mesh(v.astype(np.float64), f.astype(np.int64))
    for threshold in COACD_THRESHOLDS:
        raw = coacd.run_coacd(mesh, threshold=threshold, preprocess_mode="off", seed=0)
        got = [(np.asarray(pv, np.float32), np.asarray(pf, np.int32)) for pv, pf in raw]
        if not parts_in_hole(got, origin, profile, half, depth):
            return got
    raise HoleSpecError(
        source,
        "body",
        "the convex decomposition keeps reaching into the hole even at CoACD "
        f"threshold {COACD_THRESHOLDS[-1]}; simplify the body around the hole",
    )


# --------------------------------------------------------------------------------------------
# entry point
# --------------------------------------------------------------------------------------------


def geometry_key(spec: HoleSpec, profile: str, clearance: float, depth: float) -> str:
    payload = {
        "v": BUILD_VERSION,
        "kind": spec.body_kind,
        "body": spec.body,
        "hole_at": spec.hole_at,
        "profile": profile,
        "clearance": round(clearance, 9),
        "depth": round(depth, 9),
    }
    if spec.hole_frame is not None:  # only then: older cache keys stay valid
        payload["hole_frame"] = spec.hole_frame
    if spec.mesh_file is not None:
        payload["mesh_sha"] = hashlib.sha256(spec.mesh_file.read_bytes()).hexdigest()
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()[:20]


def _load_cached(path: Path, spec: HoleSpec, profile, clearance, depth, key) -> HoleGeometry:
    with np.load(path) as z:
        n = int(z["n_parts"])
        parts = [(z[f"part{i}_v"], z[f"part{i}_f"]) for i in range(n)]
        return HoleGeometry(
            name=spec.name,
            profile=profile,
            clearance=clearance,
            depth=depth,
            visual_vertices=z["visual_v"],
            visual_faces=z["visual_f"],
            collision_parts=parts,
            hole_frame=z["hole_frame"],
            body_height=float(z["body_height"]),
            cache_key=key,
        )


def build_geometry(
    spec: HoleSpec,
    profile: str,
    clearance: float = DEFAULT_CLEARANCE,
    depth: float = DEFAULT_HOLE_DEPTH,
    use_cache: bool = True,
) -> HoleGeometry:
    """Cut the hole for `profile` into the body and decompose it (cached on disk)."""
    if profile not in spec.hole:
        raise HoleSpecError(
            spec.source,
            "hole",
            f"this object hosts {list(spec.hole)} pegs, not a {profile} peg; "
            f"add '{profile}' to its hole list or pick another object",
        )
    if clearance <= 0 or depth <= 0:
        raise ValueError(f"clearance and depth must be > 0 (got {clearance}, {depth})")
    key = geometry_key(spec, profile, clearance, depth)
    path = cache_dir() / f"{key}.npz"
    if use_cache and path.is_file():
        try:
            return _load_cached(path, spec, profile, clearance, depth, key)
        except (OSError, KeyError, ValueError) as e:  # torn or stale file: rebuild it
            log.warning("ignoring unreadable cache file %s (%s)", path, e)

    body, at, z_open = oriented_body(spec)
    origin = check_room(spec, body, profile, clearance, depth, at, z_open)
    half = hole_half_extent(profile, clearance)
    cut = body - hole_solid(profile, half, origin[2] - depth, origin[2] + 1.0, at)
    v, f = _from_manifold(cut)
    parts = convex_decomposition(cut, origin, profile, half, clearance, depth, spec.source)
    height = float(v[:, 2].max())

    arrays = {"visual_v": v, "visual_f": f, "hole_frame": origin, "body_height": height}
    arrays["n_parts"] = np.array(len(parts))
    for i, (pv, pf) in enumerate(parts):
        arrays[f"part{i}_v"], arrays[f"part{i}_f"] = pv, pf
    path.parent.mkdir(parents=True, exist_ok=True)
    # Write to a temp file and publish it with a hard link, which fails if the entry exists:
    # with several processes building the same key at once, the first one wins and every
    # process returns that entry, so all of them simulate the same geometry.
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp.npz")
    os.close(fd)
    try:
        np.savez(tmp, **arrays)
        try:
            os.link(tmp, path)
        except FileExistsError:
            try:
                return _load_cached(path, spec, profile, clearance, depth, key)
            except (OSError, KeyError, ValueError):  # an unreadable old entry: replace it
                os.replace(tmp, path)
        except OSError:  # a file system without hard links: last writer wins
            os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return HoleGeometry(spec.name, profile, clearance, depth, v, f, parts, origin, height, key)
