"""Weights files: one torch file per network with everything needed to trust it.

A weights file holds the state dict plus: which network (policies/networks.py), its architecture
config, the task and peg profile of its training data, the data file's sha256, the
training arguments, the validation metrics and the wall time. Loading checks all of it
and says exactly what is wrong with a file that does not fit.
"""

from __future__ import annotations

import dataclasses
import json
import os
import pickle
import sys
from pathlib import Path
from typing import Any

import torch

from cfvs_maniskill.errors import FileFieldError
from cfvs_maniskill.provenance import (
    file_sha256 as file_sha256,  # re-exported: callers hash data files
)
from cfvs_maniskill.provenance import note_loaded

WEIGHTS_FORMAT = "cfvs_maniskill.weights/1"


class WeightsError(ValueError):
    """A weights file that cannot be used; the message names the file and what it holds."""


class WeightsTableError(FileFieldError, WeightsError):
    """A weights folder's `tasks.yaml` that cannot be used: file, field, what was expected."""


def safe_load(path: Path, error: type[Exception]) -> Any:
    """A torch file's contents, unpickled with `weights_only=True`: tensors and plain data
    only, so a file holding pickled code is refused before any of it runs."""
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as e:
        # torch's message names the global it refused (e.g. posix.system); keep its first line.
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise error(
            f"{path}: refused: holds objects other than tensors and plain data, which are "
            f"never unpickled ({first})"
        ) from e
    except Exception as e:  # truncated / not a torch file: torch raises many types
        raise error(f"{path}: not a readable weights file ({type(e).__name__}: {e})") from e


def save_atomic(obj: dict, path: Path) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    torch.save(obj, tmp)
    os.replace(tmp, path)


def write_weights(out: Path, model, meta: dict, module: str, args, history: list, wall_s: float):
    """Write a weights file and its .json twin: `meta` (net, task, peg, config, data) plus
    what every training run records (arguments, command, metrics, wall time)."""
    meta = {
        "format": WEIGHTS_FORMAT,
        **meta,
        "train_args": {k: str(v) for k, v in dataclasses.asdict(args).items()},
        "command": f"python -m {module} " + " ".join(sys.argv[1:]),
        "validation": history[-1],
        "history": history,
        "wall_time_s": round(wall_s, 1),
        "torch_threads": torch.get_num_threads(),
    }
    save_atomic({**meta, "state_dict": model.state_dict()}, out)
    Path(out).with_suffix(".json").write_text(json.dumps(meta, indent=1))
    print(f"wrote {out} ({wall_s / 60:.1f} min)")
    return meta


def read_weights(path: Path | str, net: str | tuple[str, ...], peg: str | None = None) -> dict:
    """A weights file's contents, checked against what we need (`net`: the network kind, or
    a tuple of acceptable kinds; `peg`: the peg it must be trained for) and with finite
    parameters; the policy's `load_weights` builds the network from it."""
    kinds = (net,) if isinstance(net, str) else tuple(net)
    net = " or ".join(kinds)
    path = Path(path)
    if not path.is_file():
        raise WeightsError(f"{path}: weights file not found (expected a trained {net} file)")
    blob = safe_load(path, WeightsError)
    note_loaded(path)
    if not isinstance(blob, dict) or blob.get("format") != WEIGHTS_FORMAT:
        raise WeightsError(f"{path}: not a cfvs_maniskill weights file (format {WEIGHTS_FORMAT})")
    if blob.get("net") not in kinds:
        raise WeightsError(
            f"{path}: holds a {blob.get('net')} network (task {blob.get('task')}), expected {net}"
        )
    if peg is not None and blob.get("peg") != peg:
        raise WeightsError(
            f"{path}: trained for a {blob.get('peg')} peg (task {blob.get('task')}), "
            f"this task uses a {peg} peg"
        )
    state = blob.get("state_dict")
    if not isinstance(state, dict):
        raise WeightsError(f"{path}: holds no state_dict (expected a trained {net} file)")
    broken = [k for k, v in state.items() if torch.is_tensor(v) and not torch.isfinite(v).all()]
    if broken:  # a diverged training run saves these, and they load without a word
        raise WeightsError(
            f"{path}: parameter '{broken[0]}' holds NaN or infinity ({len(broken)} tensors): "
            "the training that wrote it diverged; retrain or restore the file"
        )
    return blob
