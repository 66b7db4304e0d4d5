"""The true wrench of the peg's contacts, what a wrist force/torque sensor measures."""

from __future__ import annotations

import numpy as np


def contact_wrench(scene, peg_entity, origin: np.ndarray, rate: float):
    """The summed wrench of all contacts on `peg_entity` in the last physics step, world
    frame: force (N) and its moment (N m) about `origin`. PhysX reports impulses over one
    physics step, so `rate` (the physics frequency) turns them into forces."""
    force, moment = np.zeros(3), np.zeros(3)
    for c in scene.px.get_contacts():
        sign = (
            1.0
            if c.bodies[0].entity == peg_entity
            else -1.0
            if c.bodies[1].entity == peg_entity
            else 0
        )
        if sign == 0:
            continue
        for point in c.points:  # the impulse acts on the contact's first body
            f = sign * rate * np.asarray(point.impulse, np.float64)
            force += f
            moment += np.cross(np.asarray(point.position, np.float64) - origin, f)
    return force, moment
