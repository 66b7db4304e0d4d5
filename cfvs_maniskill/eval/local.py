"""Local backend: a pool of worker processes on this machine (1 = in this process)."""

from __future__ import annotations

import multiprocessing as mp
from collections.abc import Callable, Iterator

from cfvs_maniskill.eval.jobs import Job
from cfvs_maniskill.eval.worker import Worker, WorkerConfig, init_process, run_in_process


def run_local(
    jobs: list[Job], workers: int, cfg: WorkerConfig, address: str | None = None
) -> Iterator[dict]:
    """Yield result records as episodes finish (in any order)."""
    if workers <= 1:
        w = Worker(cfg)
        try:
            for job in jobs:
                yield w.run(job)
        finally:
            w.close()
        return
    # spawn: a fresh interpreter per worker (SAPIEN and torch do not survive fork well).
    ctx = mp.get_context("spawn")
    pool = ctx.Pool(workers, initializer=init_process, initargs=(cfg,), maxtasksperchild=None)
    try:
        yield from pool.imap_unordered(run_in_process, jobs, chunksize=1)
        pool.close()
    finally:
        pool.terminate()
        pool.join()


def _ray(jobs: list[Job], workers: int, cfg: WorkerConfig, address: str | None = None):
    from cfvs_maniskill.eval.ray_backend import run_ray

    return run_ray(jobs, workers, cfg, address=address)


BACKENDS: dict[str, Callable[..., Iterator[dict]]] = {"local": run_local, "ray": _ray}
