"""Dataset files: HDF5 with a documented layout, written so that no kill loses or repeats work.

Layout (`FORMAT`), one row per sample along the first axis of every dataset:

    /                   attrs: format, kind (coarse|fine), task, peg, num_points, seed,
                        frame ("tool"), config (JSON of the collect arguments), task_config
                        (JSON of the task file), keypoint_spacing, confidence_sigma, units
    points      (M, N, 3)    float32  cloud in the tool frame at capture, metres
    tcp_pose    (M, 4, 4)    float64  world pose of the tool (peg tip) frame at capture
    hole_pose   (M, 4, 4)    float64  world pose of the hole frame (origin: opening centre, +z out)
    object      (M,)         str      hole object name
    sample_index(M,)         int64    0..M-1: sample i is always drawn from seed (seed, i)
    coarse only:
    keypoints   (M, 3, 3)    float32  k1 (hole centre), k2 (+x), k3 (+z), tool frame
    offsets     (M, N, 3, 3) float32  offsets[i, n, j] = k_j - points[i, n]
    confidence  (M, N)       float32  w* = exp(-|x - k1|^2 / 2 sigma^2)
    init_error  (M,)         float32  distance tip -> hole centre at capture, metres
    fine only:
    action      (M, 6)       float32  (dt, dr): target = tcp @ [rotvec(dr) | dt], tool frame
    target_pose (M, 4, 4)    float64  the true pre-insertion pose (world)

Crash safety: samples are first written as small chunk files (`FILE.parts/part-*.npz`,
each written to a temporary name and renamed, so a chunk exists whole or not at all). When
the collection finishes, the HDF5 file is rebuilt from the old file plus the chunks into a
temporary file and renamed over FILE. A kill at any moment leaves FILE either as before or
complete, and the chunks say exactly which samples exist, so a restart collects only the
missing indices: N unique samples, never a duplicate.
"""

from __future__ import annotations

import io
import json
import os
import shutil
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

FORMAT = "cfvs_maniskill.dataset/1"
STRING_FIELDS = ("object",)
MATCH_ATTRS = ("kind", "task", "num_points", "seed", "objects", "procedural", "rollout_step")
"""Arguments that must agree between a file and a run that resumes or extends it."""


class DatasetError(ValueError):
    """A dataset file that cannot be used as asked; the message names file and field."""


def parts_dir(out: Path) -> Path:
    return Path(str(out) + ".parts")


def _part_files(out: Path) -> list[tuple[int, int, Path]]:
    found = []
    for p in sorted(parts_dir(out).glob("part-*.npz")):
        _, first, n = p.stem.split("-")
        found.append((int(first), int(n), p))
    return found


def write_part(out: Path, first: int, rows: dict[str, np.ndarray]) -> None:
    """Write one chunk of samples [first, first + n) atomically."""
    d = parts_dir(out)
    d.mkdir(parents=True, exist_ok=True)
    n = len(rows["sample_index"])
    final = d / f"part-{first:08d}-{n:06d}.npz"
    tmp = d / f".tmp-{first:08d}.npz"
    try:
        with open(tmp, "wb") as f:
            np.savez(f, **rows)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, final)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise write_error(tmp, e, f"the {first} samples before it are safe in {d}") from e


def write_error(path: Path, e: Exception, kept: str) -> DatasetError:
    """A failed write (disk full, file-size limit, ...): what failed and what is safe."""
    return DatasetError(
        f"{path}: cannot write ({getattr(e, 'strerror', None) or e}); {kept}; "
        "free some space and run the same command again to resume"
    )


def read_attrs(path: Path) -> dict:
    with h5py.File(path, "r") as f:
        return {k: _attr(v) for k, v in f.attrs.items()}


def _attr(v):
    return v.decode() if isinstance(v, bytes) else v.item() if isinstance(v, np.generic) else v


def existing_count(out: Path, attrs: dict) -> int:
    """How many samples already exist (final file + chunks), checking they match `attrs`."""
    n = 0
    if out.exists():
        try:
            old = read_attrs(out)
            with h5py.File(out, "r") as f:
                n = len(f["sample_index"])
        except (OSError, KeyError) as e:
            raise DatasetError(f"{out}: not a readable dataset file ({e})") from e
        check_match(out, old, attrs)
    meta = parts_dir(out) / "meta.json"
    if meta.exists():
        check_match(meta, json.loads(meta.read_text()), attrs)
    for first, k, p in _part_files(out):
        if first != n:
            raise DatasetError(f"{p}: chunk starts at sample {first}, expected {n}")
        n += k
    return n


def check_match(where: Path, old: dict, new: dict) -> None:
    if old.get("format", FORMAT) != FORMAT:
        raise DatasetError(f"{where}: field 'format': expected {FORMAT}, got {old.get('format')}")
    for k in MATCH_ATTRS:
        if str(old.get(k)) != str(new.get(k)):
            raise DatasetError(
                f"{where}: field '{k}': the file was collected with {k}={old.get(k)!r}, "
                f"this run asks {k}={new.get(k)!r}; use another --out or the same arguments"
            )


def start_parts(out: Path, attrs: dict) -> None:
    d = parts_dir(out)
    d.mkdir(parents=True, exist_ok=True)
    meta = d / "meta.json"
    if not meta.exists():
        tmp = d / ".meta.tmp"
        tmp.write_text(json.dumps(attrs, indent=1))
        os.replace(tmp, meta)


def _chunks(out: Path) -> Iterator[dict[str, np.ndarray]]:
    if out.exists():
        with h5py.File(out, "r") as f:
            m = len(f["sample_index"])
            for a in range(0, m, 256):
                yield {
                    k: (f[k].asstr()[a : a + 256] if k in STRING_FIELDS else f[k][a : a + 256])
                    for k in f
                }
    for _, _, p in _part_files(out):
        with np.load(p, allow_pickle=False) as z:
            yield {k: z[k] for k in z.files}


def finalize(out: Path, attrs: dict) -> int:
    """Merge the old file and all chunks into FILE (atomically); return the sample count."""
    if not _part_files(out):
        shutil.rmtree(parts_dir(out), ignore_errors=True)
        with h5py.File(out, "r") as f:
            return len(f["sample_index"])
    total = existing_count(out, attrs)
    tmp = out.with_name(out.name + ".tmp")
    # HDF5 builds the file in memory and Python writes it out: a write that fails (disk
    # full) is then a plain OSError here, not a half-closed HDF5 file that crashes the
    # interpreter at exit (measured: a segfault when h5py itself hit the limit).
    image = io.BytesIO()
    _merge(out, image, attrs, total)
    try:
        with open(tmp, "wb") as f:
            f.write(image.getbuffer())
            f.flush()
            os.fsync(f.fileno())
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise write_error(tmp, e, f"all {total} samples are kept in {parts_dir(out)}") from e
    os.replace(tmp, out)
    shutil.rmtree(parts_dir(out), ignore_errors=True)
    return total


def _merge(out: Path, image: io.BytesIO, attrs: dict, total: int) -> None:
    """The HDF5 file of the old file's and the chunks' samples, built in `image`."""
    with h5py.File(image, "w") as f:
        for k, v in attrs.items():
            f.attrs[k] = v
        filled = 0
        for rows in _chunks(out):
            n = len(rows["sample_index"])
            for k, v in rows.items():
                if k not in f:
                    if k in STRING_FIELDS:
                        f.create_dataset(k, (total,), dtype=h5py.string_dtype())
                    else:
                        v = np.asarray(v)
                        f.create_dataset(
                            k,
                            (total, *v.shape[1:]),
                            dtype=v.dtype,
                            chunks=(1, *v.shape[1:]) if v.ndim > 1 else None,
                            compression="lzf" if v.ndim > 2 else None,
                        )
                f[k][filled : filled + n] = np.asarray(v).astype(str) if k in STRING_FIELDS else v
            filled += n
        idx = f["sample_index"][:]
        if not np.array_equal(idx, np.arange(total)):
            raise DatasetError(f"{out}: samples are not 0..{total - 1} exactly once")
        f.flush()


def load(path: Path | str, fields: tuple[str, ...] | None = None) -> tuple[dict, dict]:
    """(attrs, arrays) of a dataset file, every requested field in memory."""
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"{path}: no such dataset file")
    try:
        with h5py.File(path, "r") as f:
            attrs = {k: _attr(v) for k, v in f.attrs.items()}
            if attrs.get("format") != FORMAT:
                raise DatasetError(
                    f"{path}: field 'format': expected {FORMAT}, got {attrs.get('format')!r}"
                )
            names = fields or tuple(f.keys())
            missing = [k for k in names if k not in f]
            if missing:
                raise DatasetError(
                    f"{path}: a {attrs.get('kind')} dataset has no field(s) {missing}; "
                    f"it holds {sorted(f.keys())}"
                )
            data = {k: (f[k].asstr()[:] if k in STRING_FIELDS else f[k][:]) for k in names}
    except OSError as e:
        raise DatasetError(f"{path}: not a readable HDF5 dataset ({e})") from e
    return attrs, data


@dataclass
class TrainingSets:
    """Several dataset files of one kind and peg as one training set: the arrays
    concatenated, each file's last `val_fraction` of samples held out for validation (so
    the validation set has every file, e.g. every sensor profile, in its share)."""

    data: dict[str, np.ndarray]
    train_idx: np.ndarray
    val_idx: np.ndarray
    attrs: list[dict]
    """Each file's attrs, in --data order."""
    files: list[Path]
    sizes: list[int]
    """Samples per file."""

    @property
    def peg(self) -> str:
        return self.attrs[0]["peg"]

    def record(self, sha256) -> dict:
        """What a weights file records about its data: one entry per file (path, sha256,
        samples, sensor profile, seed) plus the single-file fields older records have."""
        per_file = [
            {
                "path": str(f),
                "sha256": sha256(f),
                "samples": int(n),
                "sensor": json.loads(a.get("config", "{}")).get("sensor", "ideal"),
                "seed": int(a.get("seed", 0)),
            }
            for f, a, n in zip(self.files, self.attrs, self.sizes, strict=True)
        ]
        one = len(per_file) == 1
        return {
            "data": per_file[0]["path"] if one else [p["path"] for p in per_file],
            "data_sha256": per_file[0]["sha256"] if one else [p["sha256"] for p in per_file],
            "data_samples": int(sum(self.sizes)),
            "data_files": per_file,
        }


def load_sets(
    files: tuple[Path, ...] | list[Path],
    fields: tuple[str, ...],
    kind: str,
    who: str,
    val_fraction: float = 0.05,
) -> TrainingSets:
    """Load and join dataset files for training `who` (named in errors), which needs
    `kind` files of a single peg."""
    if not files:
        raise DatasetError("--data: expected at least one dataset file")
    parts, attrs, sizes, train_idx, val_idx = [], [], [], [], []
    start = 0
    for f in files:
        a, d = load(f, fields)
        if a.get("kind") != kind:
            raise DatasetError(
                f"{f}: field 'kind': {who} trains on a {kind} dataset, this file is {a.get('kind')}"
            )
        if attrs and a.get("peg") != attrs[0].get("peg"):
            raise DatasetError(
                f"{f}: field 'peg': expected {attrs[0].get('peg')!r} like {files[0]}, "
                f"got {a.get('peg')!r} (one training set is for one peg)"
            )
        m = len(d[fields[0]])
        n_val = max(1, int(m * val_fraction))
        train_idx.append(np.arange(start, start + m - n_val))
        val_idx.append(np.arange(start + m - n_val, start + m))
        parts.append(d)
        attrs.append(a)
        sizes.append(m)
        start += m
    data = {k: np.concatenate([p[k] for p in parts]) for k in fields}
    return TrainingSets(
        data=data,
        train_idx=np.concatenate(train_idx),
        val_idx=np.concatenate(val_idx),
        attrs=attrs,
        files=[Path(f) for f in files],
        sizes=sizes,
    )
