"""Local backend: worker processes on this machine, one job at a time each, supervised.

The parent hands each worker one job and waits on both its pipe and its process: a worker
that dies (segfault, SIGKILL, the OOM killer) is replaced and its job retried once, then
recorded as crashed (crash.py), so the run always ends. `multiprocessing.Pool` replaces a
dead worker but never returns its job, and the run hung."""

from __future__ import annotations

import os
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import suppress
from multiprocessing import connection, get_context

from cfvs_maniskill.errors import FileFieldError
from cfvs_maniskill.eval.crash import CrashPolicy, JobError, exit_reason
from cfvs_maniskill.eval.jobs import Job
from cfvs_maniskill.eval.worker import Worker, WorkerConfig


def _exit_with_parent(poll_s: float = 0.5) -> None:
    """End this process as soon as its parent is gone. A parent killed by SIGTERM or SIGKILL
    runs no clean-up, and its workers would otherwise finish their episode (or, in a hole's
    first collision build, minutes of CoACD) before their pipe tells them."""
    parent = os.getppid()

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(poll_s)
        os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def _serve(conn, cfg: WorkerConfig) -> None:
    """A worker process: run each job it is sent, send back the record (or the error)."""
    _exit_with_parent()
    try:
        worker, failed = Worker(cfg), None
    except Exception as e:  # e.g. no renderer: every job would die the same way
        worker, failed = None, e
    try:
        while (job := conn.recv()) is not None:
            try:
                if failed is not None:
                    raise failed
                conn.send(("ok", worker.run(job)))
            except Exception as e:  # the parent raises it, naming the job
                try:
                    conn.send(("error", e))
                except Exception:  # the exception itself does not pickle
                    conn.send(("error", RuntimeError(traceback.format_exc())))
    except (EOFError, KeyboardInterrupt):
        pass  # the parent went away or was interrupted: nothing left to do
    finally:
        if worker is not None:
            worker.close()


class _Slot:
    """One worker process and the job it is running (None: idle)."""

    def __init__(self, ctx, cfg: WorkerConfig):
        self.conn, child = ctx.Pipe()
        self.process = ctx.Process(target=_serve, args=(child, cfg), daemon=True)
        self.process.start()
        child.close()
        self.job: Job | None = None

    def give(self, job: Job) -> None:
        self.job = job
        with suppress(OSError):  # died already: its sentinel says so, handled as a death
            self.conn.send(job)

    def stop(self, wait: float) -> None:
        with suppress(OSError):
            self.conn.send(None)
        self.process.join(wait)
        if self.process.is_alive():
            self.process.kill()
            self.process.join()
        self.conn.close()


def run_local(
    jobs: list[Job],
    workers: int,
    cfg: WorkerConfig,
    address: str | None = None,
    retries: int = 1,
) -> Iterator[dict]:
    """Yield result records as episodes finish (in any order). `workers` processes (0: in
    this process, unsupervised: for debugging)."""
    if workers <= 0:
        w = Worker(cfg)
        try:
            for job in jobs:
                try:
                    rec = w.run(job)
                except FileFieldError:
                    raise  # names its file already
                except Exception as e:
                    raise JobError(job, e) from e
                yield rec
        finally:
            w.close()
        return
    # spawn: a fresh interpreter per worker (SAPIEN and torch do not survive fork well).
    ctx = get_context("spawn")
    queue = deque(jobs)
    policy = CrashPolicy(retries, cfg.search_radius)
    slots = [_Slot(ctx, cfg) for _ in range(min(workers, len(jobs)))]
    try:
        for s in slots:
            if queue:
                s.give(queue.popleft())
        while any(s.job is not None for s in slots):
            busy = [s for s in slots if s.job is not None]
            ready = connection.wait([s.conn for s in busy] + [s.process.sentinel for s in busy])
            for i, s in enumerate(slots):
                if s.job is None or (s.conn not in ready and s.process.sentinel not in ready):
                    continue
                message = None
                try:
                    if s.conn.poll():
                        message = s.conn.recv()
                except (EOFError, OSError):
                    message = None
                if message is None:
                    # Died mid-job: a fresh worker takes its place (and maybe the job again).
                    s.process.join(5)
                    record = policy.on_death(s.job, exit_reason(s.process.exitcode))
                    if record is None:
                        queue.appendleft(s.job)
                    s.job = None
                    s.stop(0)
                    slots[i] = s = _Slot(ctx, cfg)
                    if record is not None:
                        yield record
                else:
                    kind, payload = message
                    if kind == "error":
                        if isinstance(payload, FileFieldError):
                            raise payload
                        raise JobError(s.job, payload) from payload
                    s.job = None
                    yield payload
                if queue:
                    s.give(queue.popleft())
    finally:
        for s in slots:
            s.stop(10 if s.job is None else 0)


def _ray(jobs: list[Job], workers: int, cfg: WorkerConfig, address: str | None = None):
    from cfvs_maniskill.eval.ray_backend import run_ray

    return run_ray(jobs, workers, cfg, address=address)


BACKENDS: dict[str, Callable[..., Iterator[dict]]] = {"local": run_local, "ray": _ray}
