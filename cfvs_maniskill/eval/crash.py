"""What happens to a job whose worker dies (a segfault, the OOM killer, a lost node): it is
run once more in a fresh worker, and if that one dies too it is recorded as a crashed job
with the reason, so that the evaluation always ends. Shared by both backends."""

from __future__ import annotations

import signal
from collections import Counter
from dataclasses import dataclass, field

from cfvs_maniskill.eval.jobs import Job


class JobError(RuntimeError):
    """An error raised while running a job that is not the agent's (those fail the episode):
    names the job; the records already written stay and a rerun resumes after them."""

    def __init__(self, job: Job, cause: BaseException):
        self.job = job
        text = str(cause).strip().splitlines()
        super().__init__(
            f"job {job.key} (seed {job.seed}) stopped the evaluation: "
            f"{type(cause).__name__}: {text[-1] if text else ''}"
        )


def exit_reason(exitcode: int | None) -> str:
    """A dead process's exit code in words: killed by SIGKILL, exit code 1, ..."""
    if exitcode is None:
        return "vanished"
    if exitcode < 0:
        try:
            return f"killed by {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"killed by signal {-exitcode}"
    return f"exited with code {exitcode}"


@dataclass
class CrashPolicy:
    retries: int = 1
    """Fresh workers a job gets after the first one died running it."""
    search_radius: float | None = None
    """The run's executor setting, which labels its records (no-search variants)."""
    deaths: Counter = field(default_factory=Counter)

    def on_death(self, job: Job, reason: str) -> dict | None:
        """None: run the job again in a fresh worker; else its crashed-job record."""
        self.deaths[job.key] += 1
        if self.deaths[job.key] <= self.retries:
            return None
        record = crashed_record(job, reason, self.deaths[job.key])
        if self.search_radius is not None:
            record["search_radius_m"] = self.search_radius
        return record


def crashed_record(job: Job, reason: str, deaths: int) -> dict:
    """The record of a job that killed every worker it ran in: no outcome, so the report
    keeps it out of every success rate and lists it (`eval --retry-crashed` runs it again)."""
    return {
        **job.to_json(),
        "key": job.key,
        "success": False,
        "crashed": True,
        "reason": f"worker died {deaths} times running it (last: {reason})",
    }
