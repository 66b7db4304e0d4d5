"""Evaluation throughput: 2 local workers against 1, Ray k workers against 1 on a local
two-node Ray cluster, and the peak memory of one eval worker."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

from benchmarks.common import Figure

# Run a command and report the peak RSS of its largest process (the eval's worker).
# Also its CPU seconds per wall second: how many cores the run kept busy.
_PEAK = (
    "import json, resource, subprocess, sys, time; t = time.perf_counter();"
    "r = subprocess.run(sys.argv[1:]); u = resource.getrusage(resource.RUSAGE_CHILDREN);"
    "print(json.dumps({'rc': r.returncode, 'peak_mb': u.ru_maxrss / 1024,"
    " 'cores': (u.ru_utime + u.ru_stime) / (time.perf_counter() - t)}))"
)


def _eval(workers: int, per_object: int, backend: str = "local", address: str = "") -> dict:
    with tempfile.TemporaryDirectory() as out:
        args = [
            sys.executable, "-m", "cfvs_maniskill.eval", "--tasks", "PegInsert6DoF",
            "--agents", "cfvs", "--objects", "test", "--init-errors", "small",
            "--episodes-per-object", str(per_object), "--workers", str(workers),
            "--backend", backend, "--out", out,
        ]  # fmt: skip
        if address:
            args += ["--address", address]
        r = subprocess.run([sys.executable, "-c", _PEAK, *args], capture_output=True, text=True)
        m = re.search(
            r"\(([\d.]+) episodes/s; ([\d.]+) episodes/s once every worker had started\)", r.stdout
        )
        if not m:
            raise RuntimeError(f"eval failed:\n{r.stdout[-1500:]}\n{r.stderr[-1500:]}")
        usage = json.loads(r.stdout.strip().splitlines()[-1])
        n = len((Path(out) / "episodes.jsonl").read_text().splitlines())
        return {"overall": float(m[1]), "steady": float(m[2]), "episodes": n, **usage}


def measure(per_object: int = 40, ray_nodes: int = 2) -> tuple[list[Figure], str]:
    one = _eval(1, per_object)
    two = _eval(2, per_object)
    s = two["steady"] / one["steady"]
    lines = [
        f"Jobs: CFVS on PegInsert6DoF, 4 test objects x {per_object} episodes (15 cm).",
        "",
        "| backend | workers | episodes/s (steady) | episodes/s (incl. start-up) |",
        "|---|---|---|---|",
        f"| local | 1 | {one['steady']:.2f} | {one['overall']:.2f} |",
        f"| local | 2 | {two['steady']:.2f} | {two['overall']:.2f} |",
    ]
    cores_line = (
        f"One local worker keeps {one['cores']:.2f} cores busy (SwiftShader renders on its own "
        f"threads, in parallel with the episode's own work), two keep {two['cores']:.2f}: on "
        f"this {os.cpu_count()}-core machine the second worker can add at most "
        f"{os.cpu_count() / one['cores']:.2f}x (both figures include the start-up, whose "
        "shader compile is multi-threaded). Steady rates count from the moment as many "
        "episodes as workers are in, so that no worker's start-up is charged to them."
    )
    figures = [
        Figure(
            "eval episodes/s, 2 local workers / 1 worker",
            f"{s:.2f}",
            ">= 1.8",
            s >= 1.8,
            f"{two['steady']:.2f} vs {one['steady']:.2f} episodes/s",
        ),  # fmt: skip
        Figure(
            "peak memory of one eval worker",
            f"{one['peak_mb'] / 1024:.2f} GB",
            "<= 1.5 GB",
            one["peak_mb"] <= 1536,
            "largest process of a 1-worker eval (ru_maxrss)",
        ),  # fmt: skip
    ]
    try:
        import ray
        from ray.cluster_utils import Cluster
    except ImportError:
        ray_nodes, why = 0, "Ray not installed: pip install '.[ray]'"
    else:
        why = "--no-ray"
    if ray_nodes < 2:
        figures.append(Figure("Ray k workers / 1 worker", "skipped", ">= 0.8 k", None, why))
        return figures, "\n".join([*lines, "", cores_line])
    cluster = Cluster(
        initialize_head=True,
        head_node_args={"num_cpus": 1, "object_store_memory": 80 * 2**20},
    )
    for _ in range(ray_nodes - 1):
        cluster.add_node(num_cpus=1, object_store_memory=80 * 2**20)
    try:
        r1 = _eval(1, per_object, "ray", cluster.address)
        rk = _eval(ray_nodes, per_object, "ray", cluster.address)
    finally:
        ray.shutdown()
        cluster.shutdown()
    k = rk["steady"] / r1["steady"]
    lines += [
        f"| Ray, {ray_nodes}-node local cluster (1 CPU each) | 1 | {r1['steady']:.2f} | "
        f"{r1['overall']:.2f} |",
        f"| Ray, {ray_nodes}-node local cluster (1 CPU each) | {ray_nodes} | {rk['steady']:.2f} |"
        f" {rk['overall']:.2f} |",
    ]
    # "Where cores allow": k workers can only be k times faster if k times one worker's
    # cores exist; the nodes of a local cluster share this machine's cores.
    allow = one["cores"] * ray_nodes <= (os.cpu_count() or 1)
    note = f"{rk['steady']:.2f} vs {r1['steady']:.2f} episodes/s"
    met = k >= 0.8 * ray_nodes
    if not met and not allow:
        note += (
            f"; cores do not allow: one worker uses {one['cores']:.2f} of "
            f"{os.cpu_count()} cores, so {ray_nodes} can gain at most "
            f"{(os.cpu_count() or 1) / one['cores']:.2f}x"
        )
    figures.append(
        Figure(
            f"Ray {ray_nodes} workers / 1 worker, local {ray_nodes}-node cluster",
            f"{k:.2f}",
            f">= {0.8 * ray_nodes:.1f} where cores allow",
            met if met or allow else None,
            note,
        )  # fmt: skip
    )
    return figures, "\n".join([*lines, "", cores_line])
