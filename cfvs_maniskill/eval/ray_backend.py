"""Ray backend: the same jobs on a Ray cluster (`--backend ray --address HOST:PORT`, or a
local Ray instance without an address), one actor per worker.

An actor keeps its env and agents like a local worker. If an actor dies (its node goes
away, it is killed, it crashes), a fresh actor takes its place and the job is retried once,
then recorded as crashed (crash.py), as in the local backend: the run always ends. Ray is
an optional extra: `pip install .[ray]`.
"""

from __future__ import annotations

from collections.abc import Iterator

from cfvs_maniskill.eval.crash import CrashPolicy, JobError
from cfvs_maniskill.eval.jobs import Job
from cfvs_maniskill.eval.worker import Worker, WorkerConfig

ACTOR_PREFIX = "cfvs-eval-worker-"


class _Actor:
    def __init__(self, cfg: WorkerConfig):
        self.worker = Worker(cfg)

    def run(self, job: Job) -> dict:
        return self.worker.run(job)


def run_ray(
    jobs: list[Job],
    workers: int,
    cfg: WorkerConfig,
    address: str | None = None,
    retries: int = 1,
) -> Iterator[dict]:
    try:
        import ray
    except ImportError as e:
        raise SystemExit("error: --backend ray needs Ray: pip install '.[ray]'") from e
    if not ray.is_initialized():
        if address:
            ray.init(address=address, log_to_driver=False)
        else:
            # "local": a fresh instance; without it Ray joins any GCS it has seen in this process.
            ray.init(
                address="local", num_cpus=workers, include_dashboard=False, log_to_driver=False
            )
    Remote = ray.remote(num_cpus=1)(_Actor)

    def spawn(i: int):
        # Named, so that operators (and the tests) can find and kill one.
        return Remote.options(name=f"{ACTOR_PREFIX}{i}-{spawn.count}").remote(cfg)

    spawn.count = 0
    actors = [spawn(i) for i in range(workers)]
    queue = list(reversed(jobs))
    pending: dict = {}
    policy = CrashPolicy(retries, cfg.search_radius)

    def submit(i: int) -> None:
        if queue:
            job = queue.pop()
            pending[actors[i].run.remote(job)] = (i, job)

    for i in range(workers):
        submit(i)
    try:
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            i, job = pending.pop(ready[0])
            try:
                rec = ray.get(ready[0])
            except ray.exceptions.RayActorError as e:
                first = (str(e).strip().splitlines() or ["actor died"])[0]
                record = policy.on_death(job, f"Ray actor died: {first[:200]}")
                spawn.count += 1
                actors[i] = spawn(i)
                if record is None:
                    queue.append(job)  # retried next, on the fresh actor
                submit(i)
                if record is not None:
                    yield record
                continue
            except ray.exceptions.RayTaskError as e:
                cause = e.as_instanceof_cause() if hasattr(e, "as_instanceof_cause") else e
                raise JobError(job, cause) from e
            yield rec
            submit(i)
    finally:
        for a in actors:
            ray.kill(a)
