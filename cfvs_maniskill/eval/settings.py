"""What decides an episode besides its job key: the base seed, the search radius, the sensor
and task files' contents and the agent's weights. A results folder holds records of one set
of these; resuming it with other settings is refused, naming each difference, so that no
table or summary mixes them (the key alone says "already done" for a record made with other
settings)."""

from __future__ import annotations

from dataclasses import dataclass, field

from cfvs_maniskill.eval.jobs import scene_seed
from cfvs_maniskill.robots.mounts import DEFAULT_MOUNT


@dataclass
class Settings:
    seed: int
    search_radius: float
    sensors: dict[str, str] = field(default_factory=dict)
    """Sensor profile name -> sha256 of its file."""
    tasks: dict[str, str] = field(default_factory=dict)
    """Task name -> sha256 of its file."""
    weights: dict[tuple[str, str, str], dict[str, str]] = field(default_factory=dict)
    """(task, agent, camera mount) -> {weights file: sha256} the agent loads with its camera
    on that mount (agents that load none: {}): an agent may load weights trained for it."""


def differences(done: dict[str, dict], now: Settings) -> list[str]:
    """One line per setting in which a finished record differs from `now` (the first such
    record named); records without the field (older ones) are not judged on it, nor on the
    files of sensors, tasks and agents `now` does not run."""
    found: dict[str, str] = {}
    for key, rec in done.items():
        parts = key.split("|") if isinstance(key, str) else []
        if rec.get("crashed") or len(parts) not in (5, 6) or not parts[4].isdigit():
            continue  # no outcome, or not an eval job's key
        task, agent, obj, init_error, episode, *rest = parts
        sensor = rest[0] if rest else "ideal"
        expected_seed = scene_seed(task, obj, init_error, int(episode), now.seed)
        if rec.get("seed") != expected_seed:
            found.setdefault(
                "seed",
                f"--seed: job {key} ran on scene seed {rec.get('seed')}; "
                f"--seed {now.seed} gives it {expected_seed}",
            )
        radius = rec.get("search_radius_m")
        if radius is not None and radius != now.search_radius:
            found.setdefault(
                "radius", f"--search-radius: the records have {radius}, now {now.search_radius}"
            )
        prov = rec.get("provenance") or {}
        for kind, name, current in (("sensor", sensor, now.sensors), ("task", task, now.tasks)):
            entry = prov.get(kind) or {}
            if entry.get("sha256") and name in current and entry["sha256"] != current[name]:
                found.setdefault(
                    f"{kind}:{name}",
                    f"{kind} '{name}': its file ({entry.get('file')}) is not the one that made "
                    f"the records (sha256 {entry['sha256'][:12]}, now {current[name][:12]})",
                )
        expected = now.weights.get((task, agent, rec.get("mount") or DEFAULT_MOUNT))
        if "weights" in prov and expected is not None and prov["weights"] != expected:
            found.setdefault(
                f"weights:{agent}",
                f"agent {agent} on {task}: its weights {sorted(expected)} are not the ones "
                f"that made the records ({sorted(prov['weights'])}, or other contents)",
            )
    return list(found.values())
