"""What every agent does with an estimated pose: keep only the task's degrees of freedom."""

from __future__ import annotations

import numpy as np

from cfvs_maniskill import geometry as G


def constrain(task, T: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """3 / 4-DoF holes are upright, so the peg points straight down (4-DoF keeps the
    estimated yaw, 3-DoF the yaw of `ref`, e.g. the current tool pose); 6-DoF poses pass
    through unchanged. `task` is anything with a `dof` (TaskSpec, TaskConfig)."""
    if task.dof == 6:
        return T
    x = T[:3, 0] if task.dof == 4 else ref[:3, 0]
    out = np.array(T, dtype=np.float64, copy=True)
    out[:3, :3] = G.frame_with_z(np.array([0.0, 0.0, -1.0]), x)
    return out
