"""What a policy declares about its training data: the kinds of dataset sample it draws in
the simulator (`<policy>/collect.py`'s KINDS), which `python -m cfvs_maniskill.data collect
--kind NAME` collects into a resumable HDF5 file (data/collect.py)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class SampleKind:
    """One kind of dataset sample."""

    env_kwargs: dict[str, Any]
    """gym.make keywords beyond the task's: what the camera must deliver."""
    moves_first: bool
    """The sample moves the peg before it looks: the start view is not rendered."""
    draw: Callable[..., dict | None]
    """(args, task, env.unwrapped, first observation, hole pose, rng, i) -> sample i's
    arrays, or None when this draw gave no usable view (the collector draws again)."""
    check: Callable[[Any], None] = field(default=lambda args: None)
    """Refuses arguments this kind cannot use (ValueError naming the option)."""
    attrs: Callable[[Any], dict] = field(default=lambda args: {})
    """File attributes this kind's arguments add (a resumed file must match them)."""
