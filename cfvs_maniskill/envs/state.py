"""The task's part of the env state: what ManiSkill's sim state lacks to restore an episode
exactly (the sensor noise stream's position and the start's distance)."""

from __future__ import annotations

import numpy as np
import torch


def task_state(seed: int, draws: int, init_error_m: float) -> dict[str, torch.Tensor]:
    """As tensors; the 31-bit seed split into two exact 16-bit floats."""
    return dict(
        noise=torch.tensor([[seed >> 16, seed & 0xFFFF, draws]], dtype=torch.float32),
        init_error=torch.tensor([[init_error_m]], dtype=torch.float32),
    )


def read_task_state(task: dict) -> tuple[int, int, float]:
    """(seed, draws, init_error_m) back from `task_state`'s tensors."""
    hi, lo, draws = (int(round(float(x))) for x in np.asarray(task["noise"]).reshape(-1))
    return (hi << 16) | lo, draws, float(np.asarray(task["init_error"]).reshape(-1)[0])


def unflatten(state: torch.Tensor, template: dict, env_id: str) -> dict:
    """A flat state (as get_state() gives it) back into `template`'s nested structure."""

    def walk(template: dict, start: int) -> tuple[dict, int]:
        out = {}
        for k, v in template.items():
            if isinstance(v, dict):
                out[k], start = walk(v, start)
                continue
            n = v.shape[-1] if v.ndim > 1 else 1
            out[k] = state[:, start : start + n]
            start += n
        return out, start

    state_dict, used = walk(template, 0)
    if used != state.shape[-1]:
        raise ValueError(
            f"{env_id}: a flat state of {state.shape[-1]} values, expected "
            f"{used} (get_state()'s length for this env)"
        )
    return state_dict
