"""Every policy's networks by the kind a weights file names, and the loading that builds
one from its file (nets/checkpoint.py checks the file)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from cfvs_maniskill.nets.checkpoint import WeightsError, read_weights
from cfvs_maniskill.policies.cfvs.oakn import OAKN, OAKNConfig
from cfvs_maniskill.policies.cfvs.opn import OPN, OPNConfig
from cfvs_maniskill.policies.kovis.model import KOVIS, KOVISConfig

NETS = {
    "oakn": (OAKN, OAKNConfig),
    "opn": (OPN, OPNConfig),
    "opnv": (OAKN, OAKNConfig),
    "kovis": (KOVIS, KOVISConfig),
}
"""opnv: the fine stage as dense keypoint voting (OAKN's architecture on the fine crop);
see policies/cfvs/train.py for why it replaced the global-regression OPN in the shipped
agent."""


def build(net: str, config: dict[str, Any]):
    """The network of kind `net` with the architecture `config` (unknown keys ignored)."""
    cls, cfg_cls = NETS[net]
    known = {f.name for f in dataclasses.fields(cfg_cls)}
    kw = {k: tuple(v) if isinstance(v, list) else v for k, v in config.items() if k in known}
    return cls(cfg_cls(**kw))


def load_weights(path: Path | str, net: str | tuple[str, ...], peg: str | None = None):
    """(model in eval mode, metadata) from a weights file, checked against what we need
    (`net`: the network kind, or a tuple of acceptable kinds; `read_weights`)."""
    blob = read_weights(path, net, peg)
    model = build(blob["net"], blob["config"])
    try:
        model.load_state_dict(blob["state_dict"])
    except RuntimeError as e:
        kind = blob["net"]  # one `read_weights` accepted
        raise WeightsError(f"{path}: weights do not fit the {kind} architecture: {e}") from e
    model.eval()
    return model, blob
