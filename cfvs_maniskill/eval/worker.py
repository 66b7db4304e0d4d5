"""One evaluation worker: keeps one env per (task, obs mode) and one agent per (task,
agent) for its whole life, so the scene build and the renderer's first-frame shader
compile happen once per worker, not once per episode."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from cfvs_maniskill import provenance
from cfvs_maniskill.constants import DEFAULT_SEARCH_RADIUS
from cfvs_maniskill.eval.jobs import Job


@dataclass
class WorkerConfig:
    objects: dict[str, list[str]]
    """Objects per task (the env holds all of them; each job picks one)."""
    assets: list[str] = field(default_factory=list)
    search_radius: float = DEFAULT_SEARCH_RADIUS
    sensor_files: dict[str, str] = field(default_factory=dict)
    """Sensor profile name -> the file it came from (profiles given as paths)."""
    task_files: dict[str, str] = field(default_factory=dict)
    """Task name -> the file it came from (a task given by path, or a bundled one)."""


class Worker:
    def __init__(self, cfg: WorkerConfig):
        import torch

        # One torch thread in every worker, however many workers: processes scale better
        # than threads here, and the thread count changes float sums (point clouds, nets),
        # so with it fixed an episode's record does not depend on --workers.
        torch.set_num_threads(1)
        # The code version as this process loads the code, not minutes later at its first
        # record (a first hole build), when the checkout may have moved on.
        provenance.code_version()
        self.cfg = cfg
        self.envs: dict[tuple, object] = {}
        self.sessions: dict[tuple[str, str, str], object] = {}

    def _env(self, task: str, agent: str, sensor: str):
        """One env per (task, the agent's env options, sensor): agents that see the same
        observations share it."""
        from cfvs_maniskill.policies.registry import agent_env_kwargs
        from cfvs_maniskill.session import make_env

        key = (task, tuple(sorted(agent_env_kwargs(agent).items())), sensor)
        if key not in self.envs:
            self.envs[key] = make_env(
                self.cfg.task_files.get(task, task),
                agent,
                objects=self.cfg.objects[task],
                assets=self.cfg.assets,
                sensor=self.cfg.sensor_files.get(sensor, sensor),
            )
        return self.envs[key]

    def _session(self, task: str, agent: str, sensor: str):
        from cfvs_maniskill.session import open_session

        key = (task, agent, sensor)
        if key not in self.sessions:
            env = self._env(task, agent, sensor)
            self.sessions[key] = open_session(env, agent, self.cfg.search_radius)
        return self.sessions[key]

    def run(self, job: Job) -> dict:
        """One episode -> its result record (the run command's fields + the job's)."""
        t0 = time.perf_counter()
        session = self._session(job.task, job.agent, job.sensor)
        u = session.env.unwrapped
        u.init_error_m = u.task.init_error[job.init_error]
        r = session.episode(job.seed, options={"object": job.object})
        rec = r.to_json()
        rec.update(
            key=job.key,
            init_error=job.init_error,
            episode=job.episode,
            agent=job.agent,
            search_radius_m=self.cfg.search_radius,  # the executor setting: labels variants
            insertion=session.executor.insertion_mode,  # position (paper) or force-guided
            wall_time_s=round(time.perf_counter() - t0, 3),  # incl. any env / agent set-up
        )
        return rec

    def close(self) -> None:
        for env in self.envs.values():
            env.close()
