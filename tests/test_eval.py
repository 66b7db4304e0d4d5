"""The evaluation runner: resumable, exactly once, deterministic."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from .conftest import ROOT, quiet, run_cli

ARGS = [
    "--tasks", "PegInsert3DoF", "--agents", "oracle", "icp",
    "--objects", "cuboid_test_1", "cylinder", "--init-errors", "small",
    "--episodes-per-object", "3",
]  # fmt: skip
EPISODES = 3
JOBS = 1 * 2 * 2 * 1 * EPISODES


def _records(path: Path) -> dict[str, dict]:
    recs = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    keys = [r["key"] for r in recs]
    assert len(keys) == len(set(keys)), "a job was recorded twice"
    return {r["key"]: {k: v for k, v in r.items() if k != "wall_time_s"} for r in recs}


def _outcome(rec: dict) -> dict:
    """A record up to float noise: a worker that ran other episodes first carries PhysX
    solver state that moves final measurements by ~0.01 mm and the peg's end tilt by
    ~0.01 deg (never the outcome)."""
    return {
        k: round(v, 1 if k.endswith("_deg") else 3)
        if isinstance(v, float)
        else re.sub(r"\d+\.\d+", "N", v)
        if k == "reason"
        else v
        for k, v in rec.items()
    }


def _same_outcomes(a: dict[str, dict], b: dict[str, dict]) -> bool:
    return a.keys() == b.keys() and all(_outcome(a[k]) == _outcome(b[k]) for k in a)


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> dict[str, dict]:
    out = tmp_path_factory.mktemp("eval_ref")
    r = run_cli("cfvs_maniskill.eval", *ARGS, "--workers", "1", "--out", str(out))
    assert r.returncode == 0, r.stderr[-2000:]
    recs = _records(out / "episodes.jsonl")
    assert len(recs) == JOBS
    assert (out / "summary.md").is_file()
    return recs


def _worker_pids(pid: int) -> list[int]:
    import psutil

    # spawn's workers; not its resource tracker
    kids = psutil.Process(pid).children()
    return [c.pid for c in kids if "spawn_main" in " ".join(c.cmdline())]


@pytest.mark.slow
def test_a_killed_worker_is_replaced_and_its_job_retried(reference, tmp_path):
    """One worker SIGKILLed mid-run (as a segfault or the OOM killer would): the run ends on
    its own with every job recorded exactly once, as the uninterrupted run; a re-run finds
    nothing to do."""
    path = tmp_path / "episodes.jsonl"
    cmd = [sys.executable, "-m", "cfvs_maniskill.eval", *ARGS, "--workers", "2",
           "--out", str(tmp_path)]  # fmt: skip
    p = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 300
    while time.time() < deadline and p.poll() is None:
        if path.exists() and len(path.read_text().splitlines()) >= 2:
            break
        time.sleep(0.05)
    workers = _worker_pids(p.pid)
    assert p.poll() is None and len(workers) == 2, "no running workers to kill"
    os.kill(workers[0], signal.SIGKILL)
    out, err = p.communicate(timeout=600)  # a hang fails here
    assert p.returncode == 0, err[-2000:]
    assert _same_outcomes(_records(path), reference)
    assert not any(r.get("crashed") for r in _records(path).values())
    r = run_cli("cfvs_maniskill.eval", *ARGS, "--workers", "2", "--out", str(tmp_path))
    assert r.returncode == 0 and "0 to run" in r.stdout, r.stderr[-2000:]


@pytest.mark.slow
def test_workers_end_when_the_evaluation_is_killed(tmp_path):
    """The evaluation SIGKILLed (no clean-up runs) while its workers are deep in a job that
    takes ten minutes: they exit by themselves within seconds instead of running on."""
    import psutil

    cmd = [sys.executable, "-m", "cfvs_maniskill.eval", "--tasks", "PegInsert3DoF",
           "--agents", "tests.crashing_agent:StuckAgent", "--objects", "cuboid_test_1",
           "--init-errors", "small", "--episodes-per-object", "2", "--workers", "2",
           "--out", str(tmp_path)]  # fmt: skip
    p = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 300
    workers: list = []
    while time.time() < deadline and p.poll() is None:
        workers = [psutil.Process(pid) for pid in _worker_pids(p.pid)]
        # Both stuck in the agent's decision: asleep, having used their start-up CPU.
        if len(workers) == 2 and all(w.status() == psutil.STATUS_SLEEPING for w in workers):
            cpu = [w.cpu_times().user for w in workers]
            time.sleep(2)
            if all(w.cpu_times().user - c < 0.05 for w, c in zip(workers, cpu, strict=True)):
                break
        time.sleep(0.5)
    assert p.poll() is None and len(workers) == 2, "no workers in their job"
    p.kill()
    p.wait()
    gone, alive = psutil.wait_procs(workers, timeout=10)
    for w in alive:
        w.kill()
    assert not alive, f"{len(alive)} workers outlived the killed evaluation by 10 s"


@pytest.mark.slow
def test_a_job_that_kills_every_worker_is_recorded_as_crashed(tmp_path):
    """A job whose worker dies twice (here: an agent that SIGKILLs its own process) is
    recorded as crashed with the signal; the other jobs finish and the run ends. The report
    keeps crashed jobs out of success rates and lists them; --retry-crashed runs them
    again."""
    crasher = "tests.crashing_agent:CrashingAgent"
    args = ["--tasks", "PegInsert3DoF", "--agents", "oracle", crasher, "--objects",
            "cuboid_test_1", "--init-errors", "small", "--episodes-per-object", "1",
            "--workers", "2", "--out", str(tmp_path / "run")]  # fmt: skip
    r = run_cli("cfvs_maniskill.eval", *args)
    assert r.returncode == 0, r.stderr[-2000:]
    recs = _records(tmp_path / "run" / "episodes.jsonl")
    assert len(recs) == 2
    crashed = [x for x in recs.values() if x.get("crashed")]
    assert [x["agent"] for x in crashed] == [crasher]
    assert all("died 2 times" in x["reason"] and "SIGKILL" in x["reason"] for x in crashed)
    assert all(x["success"] for x in recs.values() if x["agent"] == "oracle")
    summary = (tmp_path / "run" / "summary.md").read_text()
    assert "1 crashed jobs" in summary
    r = run_cli("cfvs_maniskill.eval", *args)
    assert "0 to run" in r.stdout
    r = run_cli("cfvs_maniskill.eval", *args, "--retry-crashed")
    assert r.returncode == 0 and "1 to run" in r.stdout, r.stderr[-2000:]


@pytest.mark.slow
def test_torn_last_line_is_redone_and_nothing_else_lost(reference, tmp_path):
    lines = [json.dumps({**r, "wall_time_s": 0.0}) for r in reference.values()]
    path = tmp_path / "episodes.jsonl"
    path.write_text("\n".join(lines[:-1]) + "\n" + lines[-1][: len(lines[-1]) // 2])
    r = run_cli("cfvs_maniskill.eval", *ARGS, "--workers", "1", "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr[-2000:]
    assert "1 to run" in r.stdout
    assert _same_outcomes(_records(path), reference)


@pytest.mark.slow
def test_same_arguments_give_identical_records(reference, tmp_path):
    """One worker, same seeds: the JSON lines are identical apart from wall times."""
    r = run_cli("cfvs_maniskill.eval", *ARGS, "--workers", "1", "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr[-2000:]
    assert _records(tmp_path / "episodes.jsonl") == reference


def test_bad_line_in_the_middle_is_named(tmp_path):
    (tmp_path / "episodes.jsonl").write_text('{"key": "a"}\nnot json\n{"key": "b"}\n')
    r = run_cli("cfvs_maniskill.eval", *ARGS, "--out", str(tmp_path))
    assert r.returncode == 2
    assert "line 2" in r.stderr and "episodes.jsonl" in r.stderr


def test_an_object_only_a_worker_finds_unusable_is_named_and_saved_episodes_stay(tmp_path):
    # The file parses (so the runner starts), but its box is too thin for the hole: only
    # the worker that builds the body finds out, in another process.
    assets = tmp_path / "assets"
    assets.mkdir()
    (assets / "thin.yaml").write_text(
        "name: thin_box\nsplit: test\nbody:\n  box: {size: [0.2, 0.2, 0.03]}\n"
        "hole_frame:\n  origin: [0.0, 0.0, 0.03]\n  axis: [0.0, 0.0, 1.0]\n"
    )
    out = tmp_path / "out"
    out.mkdir()
    kept = '{"key": "earlier", "success": true}\n'
    (out / "episodes.jsonl").write_text(kept)
    r = run_cli(
        "cfvs_maniskill.eval", "--assets", str(assets), "--objects", "thin_box",
        "--tasks", "PegInsert3DoF", "--agents", "oracle", "--init-errors", "small",
        "--episodes-per-object", "1", "--workers", "1", "--out", str(out),
    )  # fmt: skip
    assert r.returncode == 1, r.stderr[-2000:]
    assert "thin.yaml" in r.stderr and "body.box.size" in r.stderr and "Traceback" not in r.stderr
    assert (out / "episodes.jsonl").read_text() == kept


@pytest.mark.parametrize(
    ("flag", "value", "valid"),
    [
        ("--agents", "nope", "cfvs"),
        ("--agents", "cfvs@/no/such/weights", "no weights folder"),
        ("--tasks", "Nope", "PegInsert6DoF"),
        ("--objects", "nope", "test"),
    ],
)
def test_unknown_names_exit_2_listing_valid_ones(tmp_path, flag, value, valid):
    r = run_cli("cfvs_maniskill.eval", flag, value, "--out", str(tmp_path))
    assert r.returncode == 2
    assert value in r.stderr and valid in r.stderr


@pytest.mark.slow
@pytest.mark.xdist_group("ray")  # one Ray at a time on this machine
def test_ray_backend_retries_killed_workers_and_records_once(reference):
    """Local Ray instance, 2 actors; both are killed after the first result (one of them
    mid-episode): their episodes go to fresh actors and every job is recorded once, with
    the outcomes of the local run."""
    ray = pytest.importorskip("ray")
    from cfvs_maniskill.eval.__main__ import EvalArgs, resolve
    from cfvs_maniskill.eval.jobs import make_jobs
    from cfvs_maniskill.eval.ray_backend import ACTOR_PREFIX, run_ray
    from cfvs_maniskill.eval.worker import WorkerConfig

    args = EvalArgs(
        tasks=("PegInsert3DoF",),
        agents=("oracle", "icp"),
        objects=("cuboid_test_1", "cylinder"),
        init_errors=("small",),
        episodes_per_object=EPISODES,
    )  # fmt: skip  (the same jobs as ARGS)
    objects = resolve(args)
    jobs = make_jobs(objects, list(args.agents), ["small"], args.episodes_per_object, 0)
    # "local": Ray caches the GCS addresses it found in this process, so after the two-node
    # test a bare ray.init() tries to join that dead cluster.
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        got = []
        for rec in run_ray(jobs, 2, WorkerConfig(objects=objects)):
            got.append(rec)
            if len(got) == 1:
                for i in range(2):
                    ray.kill(ray.get_actor(f"{ACTOR_PREFIX}{i}-0"))
    finally:
        ray.shutdown()
    keys = [r["key"] for r in got]
    assert len(keys) == len(set(keys)) == JOBS
    recs = {r["key"]: {k: v for k, v in r.items() if k != "wall_time_s"} for r in got}
    assert _same_outcomes(recs, reference)


@pytest.mark.slow
@pytest.mark.xdist_group("ray")  # one Ray at a time on this machine
def test_ray_backend_on_a_two_node_cluster(reference, tmp_path):
    """`--backend ray --address` on a two-node `ray.cluster_utils.Cluster` with one CPU
    per node: the two actors can only run on different nodes, so finishing at all shows
    both nodes worked; the records are the local run's."""
    pytest.importorskip("ray")
    from ray.cluster_utils import Cluster

    node = {"num_cpus": 1, "object_store_memory": 80 * 2**20}
    cluster = Cluster(initialize_head=True, head_node_args=node)
    cluster.add_node(**node)
    args = [a for a in ARGS if a != "icp"]  # oracle only: quick episodes
    try:
        r = run_cli(
            "cfvs_maniskill.eval", *args, "--backend", "ray", "--address", cluster.address,
            "--workers", "2", "--out", str(tmp_path),
        )  # fmt: skip
    finally:
        cluster.shutdown()
    assert r.returncode == 0, r.stderr[-2000:]
    want = {k: v for k, v in reference.items() if v["agent"] == "oracle"}
    assert _same_outcomes(_records(tmp_path / "episodes.jsonl"), want)


def _results_folder(reference: dict[str, dict], tmp_path: Path) -> Path:
    """tmp/results/eval/episodes.jsonl holding the reference run's records."""
    res = tmp_path / "results" / "eval"
    res.mkdir(parents=True)
    lines = [json.dumps({**r, "wall_time_s": 1.0}) for r in reference.values()]
    (res / "episodes.jsonl").write_text("\n".join(lines) + "\n")
    return tmp_path / "results"


def test_report_writes_tables_beside_the_paper_and_plots(reference, tmp_path):
    results = _results_folder(reference, tmp_path)
    out = tmp_path / "report"
    r = run_cli("cfvs_maniskill.report", str(results), "--out", str(out), "--no-videos")
    assert r.returncode == 0, r.stderr[-2000:]
    text = (out / "README.md").read_text()
    assert "Table II" in text and "Table III" in text and "Table IV" in text
    # icp on 3-DoF: our cell beside the paper's 0.10 average
    row = next(line for line in text.splitlines() if line.startswith("| icp |"))
    assert "(n=6)" in row and "| 0.10 |" in row
    for name in ("success_per_agent", "success_vs_tilt", "servo_time"):
        assert (out / f"{name}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_report_videos_replay_the_recorded_episodes(reference, tmp_path):
    import imageio_ffmpeg
    import numpy as np

    results = _results_folder(reference, tmp_path)
    # An episode of an agent this code no longer has: listed, not rendered, saying why.
    odd = {**next(iter(reference.values())), "agent": "cfvs_no_aug", "key": "odd"}
    with open(results / "eval" / "episodes.jsonl", "a") as f:
        f.write(json.dumps(odd) + "\n")
    out = tmp_path / "report"
    r = run_cli("cfvs_maniskill.report", str(results), "--out", str(out), "--video-variants")
    assert r.returncode == 0, r.stderr[-2000:]
    assert quiet(r.stderr), r.stderr[-2000:]  # replaying made envs: no driver lines shown
    text = (out / "README.md").read_text()
    shown = text.split("## Videos")[1]
    row = next(x for x in shown.splitlines() if x.startswith("| PegInsert3DoF | cfvs_no_aug |"))
    assert "not rendered" in row and "unknown agent 'cfvs_no_aug'" in row
    outcomes = {(v["agent"], v["success"]) for v in reference.values()}
    for agent, success in outcomes:  # first success and first failure of each agent
        name = f"PegInsert3DoF_{agent}_{'success' if success else 'failure'}.mp4"
        assert f"(videos/{name})" in text
        reader = imageio_ffmpeg.read_frames(str(out / "videos" / name))
        next(reader)  # metadata
        frames = np.stack([np.frombuffer(f, np.uint8) for f in reader])
        assert len(frames) > 20 and frames.std() > 1  # a non-blank picture over time
        replayed = (out / "videos" / name).with_suffix(".txt").read_text()
        assert replayed.startswith("success" if success else "failure")
    # a second report keeps the rendered files instead of replaying them again
    before = {p: p.stat().st_mtime_ns for p in (out / "videos").iterdir()}
    r = run_cli("cfvs_maniskill.report", str(results), "--out", str(out), "--video-variants")
    assert r.returncode == 0 and before == {
        p: p.stat().st_mtime_ns for p in (out / "videos").iterdir()
    }


def test_a_rendered_video_is_kept_only_for_the_episode_it_shows(tmp_path):
    """A video's file name says task, agent and outcome; what it shows is the episode of
    one job, seed and code: a re-run with other code or another seed renders it anew."""
    from cfvs_maniskill.report.videos import IDENTITY, _kept, episode_identity

    rec = {"key": "T|cfvs|box|small|0", "seed": 7, "provenance": {"code_fingerprint": "ab"}}
    video, meta = tmp_path / "v.mp4", tmp_path / "v.txt"
    video.write_bytes(b"mp4")
    meta.write_text(f"failure peg on the rim\n{IDENTITY}{episode_identity(rec)}\n")
    assert _kept(video, meta, rec) == (False, "peg on the rim")
    assert _kept(video, meta, {**rec, "seed": 8}) is None
    assert _kept(video, meta, {**rec, "provenance": {"code_fingerprint": "cd"}}) is None
    meta.write_text("success \n")  # a video that does not say which episode it shows
    assert _kept(video, meta, rec) is None


def test_videos_of_episodes_no_longer_picked_leave_the_report(tmp_path):
    from cfvs_maniskill.report.videos import prune, video_name

    rec = {"task": "PegInsert3DoF", "label": "cfvs", "success": True}
    shown = video_name(rec)
    for stem in (shown, "PegInsert3DoF_cfvs_failure", "PegInsert6DoF_old_agent_success"):
        (tmp_path / f"{stem}.mp4").write_bytes(b"mp4")
        (tmp_path / f"{stem}.txt").write_text("success\n")
    (tmp_path / "notes.md").write_text("not a film")
    gone = prune(tmp_path, {shown})
    assert sorted(f.name for f in gone) == [
        "PegInsert3DoF_cfvs_failure.mp4", "PegInsert3DoF_cfvs_failure.txt",
        "PegInsert6DoF_old_agent_success.mp4", "PegInsert6DoF_old_agent_success.txt",
    ]  # fmt: skip
    assert sorted(f.name for f in tmp_path.iterdir()) == [
        f"{shown}.mp4",
        f"{shown}.txt",
        "notes.md",
    ]


def test_every_record_says_which_code_weights_sensor_task_and_object_made_it(reference):
    from cfvs_maniskill.constants import PROJECT_ROOT
    from cfvs_maniskill.provenance import code_version, sha256

    for rec in reference.values():
        p = rec["provenance"]
        assert p["code"] == code_version() and p["code"]
        assert p["weights"] == {}  # oracle and ICP from the workspace centre load none
        assert p["sensor"] == {"name": "ideal", "file": "sensors/ideal.yaml",
                               "sha256": sha256(PROJECT_ROOT / "sensors/ideal.yaml")}  # fmt: skip
        assert p["task"]["sha256"] == sha256(PROJECT_ROOT / "tasks/PegInsert3DoF.yaml")
        (hole_file,) = p["object"]["files"]
        assert hole_file == f"assets/holes/{rec['object']}.yaml"


def test_report_check_names_mixed_stale_and_crashed_cells(reference, tmp_path):
    """`report --check` passes on records of one provenance made with today's files, and
    fails naming the cell when one record comes from other code (mixed), other weights or
    an edited sensor file (stale), or a job crashed; also when the README's table is not
    what the records give."""
    results = _results_folder(reference, tmp_path)
    readme = tmp_path / "README.md"
    readme.write_text("<!-- report:headline begin -->\n<!-- report:headline end -->\n")
    check = ["cfvs_maniskill.report", str(results), "--check", "--readme", str(readme)]
    r = run_cli(*check)
    assert r.returncode == 1 and "headline tables are not what the records give" in r.stdout
    assert run_cli("cfvs_maniskill.report", str(results), "--readme", str(readme),
                   "--no-videos", "--out", str(tmp_path / "rep")).returncode == 0  # fmt: skip
    r = run_cli(*check)
    assert r.returncode == 0, r.stdout + r.stderr[-2000:]
    assert "0 problems" in r.stdout
    path = results / "eval" / "episodes.jsonl"
    clean = path.read_text()
    edits = {
        "code": lambda p: p.update(code="0123456789ab", code_fingerprint="0" * 16),
        "weights": lambda p: p["weights"].update({"agents/cfvs/round/oakn.pt": "0" * 64}),
        "sensor": lambda p: p["sensor"].update(sha256="1" * 64),
    }
    for what, edit in edits.items():
        recs = [json.loads(x) for x in clean.splitlines()]
        icp = next(x for x in recs if x["agent"] == "icp")
        edit(icp["provenance"])
        path.write_text("".join(json.dumps(x) + "\n" for x in recs))
        r = run_cli(*check)
        assert r.returncode == 1, what
        says = {"code": "mixed: 2 provenances", "weights": "other weights today",
                "sensor": "sensor file sensors/ideal.yaml changed since"}[what]  # fmt: skip
        assert "icp PegInsert3DoF ideal small: " in r.stdout and says in r.stdout, r.stdout
    recs = [json.loads(x) for x in clean.splitlines()]
    recs[0].update(crashed=True, success=False)
    path.write_text("".join(json.dumps(x) + "\n" for x in recs))
    r = run_cli(*check)
    assert r.returncode == 1 and ": crashed: " in r.stdout, r.stdout


def test_report_on_an_empty_folder_exits_2(tmp_path):
    r = run_cli("cfvs_maniskill.report", str(tmp_path), "--out", str(tmp_path / "r"))
    assert r.returncode == 2 and "no result records" in r.stderr


def test_named_object_is_skipped_for_tasks_its_peg_does_not_fit(tmp_path):
    """A named object that hosts only the square peg: the round-peg task skips that pair
    with one line; an object that fits none of the tasks stays an error."""
    from cfvs_maniskill.eval.__main__ import EvalArgs, resolve

    (tmp_path / "tri.yaml").write_text(
        "name: tri_only_square\nhole: square\nbody:\n  prism: {sides: 3, radius: 0.1, height: 0.07}\n"
    )
    args = EvalArgs(
        tasks=("PegInsert3DoF", "PegInsert6DoF"),
        objects=("tri_only_square", "cylinder"),
        assets=(tmp_path,),
    )
    assert resolve(args) == {
        "PegInsert3DoF": ["cylinder"],
        "PegInsert6DoF": ["cylinder", "tri_only_square"],
    }
    r = run_cli("cfvs_maniskill.eval", "--tasks", "PegInsert3DoF", "--objects",
                "tri_only_square", "--assets", str(tmp_path), "--out", str(tmp_path / "o"))  # fmt: skip
    assert r.returncode == 2
    assert "tri_only_square" in r.stderr and "fits none of the tasks" in r.stderr


def test_report_puts_sensor_profiles_side_by_side(reference, tmp_path):
    """Records of two sensor profiles: the paper's tables use the ideal ones only; the
    per-profile table and summary.md show both, side by side, the paper's beside."""
    results = _results_folder(reference, tmp_path)
    real = [
        {**r, "key": r["key"] + "|realistic", "sensor": "realistic", "success": False}
        for r in reference.values()
    ]
    with open(results / "eval" / "episodes.jsonl", "a") as f:
        f.write("".join(json.dumps(r) + "\n" for r in real))
    out = tmp_path / "report"
    r = run_cli("cfvs_maniskill.report", str(results), "--out", str(out), "--no-videos")
    assert r.returncode == 0, r.stderr[-2000:]
    text = (out / "README.md").read_text()
    table_ii = text.split("## Table II")[1].split("\n## ")[0]
    assert "(n=6)" in next(x for x in table_ii.splitlines() if x.startswith("| icp |"))
    per_sensor = text.split("## Success per sensor profile")[1].split("\n## ")[0]
    assert "ideal 15 cm" in per_sensor and "realistic 15 cm" in per_sensor
    oracle = next(x for x in per_sensor.splitlines() if x.startswith("| oracle |"))
    assert "1.00 [" in oracle and "0.00 [" in oracle  # ideal beside realistic
    summary = (out / "summary.md").read_text()
    icp = next(x for x in summary.splitlines() if x.startswith("| icp | 3-DoF |"))
    assert "0/6 = 0.00" in icp and icp.rstrip().endswith("0.10 / 0.10 |")

    # --readme fills the headline table between its markers, keeping the rest of the file
    readme = tmp_path / "README.md"
    readme.write_text(
        "intro\n<!-- report:headline begin -->\nold\n<!-- report:headline end -->\nend\n"
    )
    r = run_cli("cfvs_maniskill.report", str(results), "--out", str(out), "--no-videos",
                "--readme", str(readme))  # fmt: skip
    assert r.returncode == 0, r.stderr[-2000:]
    filled = readme.read_text()
    assert filled.startswith("intro\n") and filled.endswith("end\n") and "old" not in filled
    row = next(x for x in filled.splitlines() if x.startswith("| icp |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert len(cells) == 7 and cells[2] == "0.00 / -"  # 3-DoF realistic: all set to fail
    assert "| agent | 3DoF ideal | 3DoF realistic |" in filled
    readme.write_text("no markers\n")
    r = run_cli("cfvs_maniskill.report", str(results), "--out", str(out), "--no-videos",
                "--readme", str(readme))  # fmt: skip
    assert r.returncode == 2 and "report:headline begin" in r.stderr
    assert readme.read_text() == "no markers\n"


@pytest.mark.slow
def test_eval_runs_a_grid_of_sensor_profiles(tmp_path):
    """--sensors is a grid dimension: one record per profile on the same scene, each
    carrying its profile; a rerun adds nothing."""
    args = [
        "cfvs_maniskill.eval", "--tasks", "PegInsert3DoF", "--agents", "oracle",
        "--objects", "cylinder", "--init-errors", "small", "--episodes-per-object", "1",
        "--sensors", "ideal", "realistic", "--workers", "1", "--out", str(tmp_path),
    ]  # fmt: skip
    r = run_cli(*args)
    assert r.returncode == 0, r.stderr[-2000:]
    recs = [json.loads(x) for x in (tmp_path / "episodes.jsonl").read_text().splitlines()]
    assert sorted(x["sensor"] for x in recs) == ["ideal", "realistic"]
    assert {x["mount"] for x in recs} == {"tip_view"}  # each record names its mount
    assert len({x["seed"] for x in recs}) == 1 and len({x["key"] for x in recs}) == 2
    assert "| realistic |" in (tmp_path / "summary.md").read_text()
    r = run_cli(*args)
    assert r.returncode == 0 and "0 to run" in r.stdout


def test_your_own_agent_runs_through_eval_by_module_and_class(tmp_path):
    """docs/your-own-agent.md: `--agents package.module:Class` evaluates an agent nobody
    registered, beside ours, on the same scenes; a bad spec exits 2 naming it."""
    mine = "examples.top_face_agent:TopFaceAgent"
    r = run_cli(
        "cfvs_maniskill.eval",
        "--agents",
        mine,
        "oracle",
        "--tasks",
        "PegInsert3DoF",
        "--objects",
        "cuboid_test_1",
        "--init-errors",
        "small",
        "--episodes-per-object",
        "2",
        "--workers",
        "1",
        "--out",
        str(tmp_path),
    )
    assert r.returncode == 0, r.stderr[-2000:]
    rows = [json.loads(x) for x in (tmp_path / "episodes.jsonl").read_text().splitlines()]
    by_agent = {a: [x for x in rows if x["agent"] == a] for a in (mine, "oracle")}
    assert len(by_agent[mine]) == 2 and len(by_agent["oracle"]) == 2
    assert {x["seed"] for x in by_agent[mine]} == {x["seed"] for x in by_agent["oracle"]}
    # Its module is outside the package's fingerprint: the record keeps its own hash.
    from cfvs_maniskill.report.trace import stale_reasons

    rec = by_agent[mine][0]
    from cfvs_maniskill.constants import PROJECT_ROOT
    from cfvs_maniskill.provenance import sha256

    mine_file = "examples/top_face_agent.py"
    assert rec["provenance"]["agent_code"] == {mine_file: sha256(PROJECT_ROOT / mine_file)}
    assert by_agent["oracle"][0]["provenance"]["agent_code"] == {}
    assert not any("agent code" in x for x in stale_reasons(rec, rec["provenance"]))
    edited = {**rec["provenance"], "agent_code": {mine_file: "0" * 64}}
    assert f"agent code {mine_file} changed since" in stale_reasons(rec, edited)
    assert any(x["steps"] > 0 for x in by_agent[mine])  # it moved the robot
    for spec, says in [
        ("nosuch_pkg.mod:Agent", "cannot import module 'nosuch_pkg.mod'"),
        ("examples.top_face_agent:np", "not a concrete subclass"),
        ("examples.top_face_agent:Nope", "has no 'Nope'"),
    ]:
        r = run_cli("cfvs_maniskill.eval", "--agents", spec, "--out", str(tmp_path / "bad"))
        assert r.returncode == 2 and says in r.stderr and "Traceback" not in r.stderr, spec


def test_an_installed_package_names_its_agent_through_the_entry_point_group(tmp_path):
    """A package that declares `[project.entry-points."cfvs_maniskill.agents"]` makes its
    agent a plain `--agents` name (here a dist-info as pip would write it)."""
    import os
    import subprocess
    import sys

    from tests.conftest import ROOT

    dist = tmp_path / "site" / "top_face_plugin-0.1.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: top-face-plugin\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(
        "[cfvs_maniskill.agents]\ntop_face = examples.top_face_agent:TopFaceAgent\n"
    )
    env = {**os.environ, "PYTHONPATH": str(tmp_path / "site")}
    args = ["--tasks", "PegInsert3DoF", "--objects", "cuboid_test_1", "--init-errors", "small"]
    r = subprocess.run(
        [sys.executable, "-m", "cfvs_maniskill.eval", "--agents", "top_face", *args,
         "--episodes-per-object", "1", "--workers", "1", "--out", str(tmp_path / "out")],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr[-2000:]
    (row,) = [json.loads(x) for x in (tmp_path / "out" / "episodes.jsonl").read_text().splitlines()]
    assert row["agent"] == "top_face" and row["steps"] > 0


def test_agent_task_pairs_without_weights_are_skipped_with_a_line(capsys, monkeypatch, tmp_path):
    """KOVIS given weights for the round peg only: its square-peg tasks are skipped with a
    line naming the missing file; asked for square-peg tasks alone, eval exits 2."""
    from cfvs_maniskill import TASKS
    from cfvs_maniskill.eval.__main__ import unbuildable
    from cfvs_maniskill.policies.kovis import agent as K

    shutil.copy(K.WEIGHTS_DIR / "round.pt", tmp_path / "round.pt")
    build = K.KOVISAgent.__init__
    monkeypatch.setattr(
        K.KOVISAgent,
        "__init__",
        lambda self, task, cfg=None: build(self, task, K.KOVISAgentConfig(weights_dir=tmp_path)),
    )

    skip = unbuildable(["kovis", "cfvs"], {t: TASKS[t] for t in ["PegInsert3DoF", "PegInsert4DoF"]})
    assert skip == {("PegInsert4DoF", "kovis")}
    out = capsys.readouterr().out
    assert "skipping PegInsert4DoF x kovis" in out and "square.pt" in out
    with pytest.raises(SystemExit) as e:
        unbuildable(["kovis"], {t: TASKS[t] for t in ["PegInsert4DoF", "PegInsert6DoF"]})
    assert e.value.code == 2


def test_compressed_records_are_read_and_a_resumed_run_appends_beside_them(tmp_path):
    """Finished runs are kept as episodes.jsonl.gz in the repository: the report reads
    them, a resumed run counts them done and appends new records beside them, and once it
    is finished folds them into the compressed file (compressing `episodes.jsonl` again
    would otherwise put the new records in place of the old)."""
    import gzip

    from cfvs_maniskill.eval.results import append, fold_into_compressed, read_done
    from cfvs_maniskill.report.load import load_records

    lines = gzip.decompress((ROOT / "results/cfvs_ablations/episodes.jsonl.gz").read_bytes())
    records = [json.loads(x) for x in lines.splitlines()]
    assert len(load_records(ROOT / "results" / "cfvs_ablations")) == len(records) == 1600
    run = tmp_path / "run"
    run.mkdir()
    (run / "episodes.jsonl.gz").write_bytes(gzip.compress(b"\n".join(lines.splitlines()[:10])))
    path = run / "episodes.jsonl"
    assert len(read_done(path)) == 10
    append(path, {**records[10]})
    done = read_done(path)
    assert len(done) == 11 and records[10]["key"] in done
    assert len(load_records(run)) == 11
    fold_into_compressed(path)
    assert not path.exists() and sorted(read_done(path)) == sorted(done)
    assert len(gzip.decompress((run / "episodes.jsonl.gz").read_bytes()).splitlines()) == 11
    append(path, {**records[11]})  # resumed again, and killed after the fold's rename
    fold_into_compressed(path)
    append(path, {**records[11]})
    assert len(read_done(path)) == 12 and len(load_records(run)) == 12


@pytest.mark.parametrize(
    "metrics, expected",
    [
        # Recorded on a composite body: the peg went down 96 mm off the axis, 17 mm deeper
        # than the hole's bottom; it once read "stuck -17.0 mm above the hole's bottom".
        (dict(tilt_error_deg=0.0, tip_depth=0.06, lateral_offset=0.0967, tip_to_bottom=-0.017,
              wall_penetration=0.07),
         "peg went down beside the hole (96.7 mm off the axis)"),
        (dict(tilt_error_deg=0.0, tip_depth=0.05, lateral_offset=0.001, tip_to_bottom=0.012,
              wall_penetration=-0.0001),
         "peg stuck 12.0 mm above the hole's bottom"),
        (dict(tilt_error_deg=0.0, tip_depth=0.0, lateral_offset=0.002, tip_to_bottom=0.06,
              wall_penetration=float("-inf")),
         "peg stopped on the rim (2.0 mm off the axis)"),
        (dict(tilt_error_deg=12.5, tip_depth=0.02, lateral_offset=0.001, tip_to_bottom=0.04,
              wall_penetration=0.0),
         "peg tilted 12.5 deg from the hole axis"),
        # At the bottom, in the hole's section but past its wall: sunk into the wall.
        (dict(tilt_error_deg=0.1, tip_depth=0.045, lateral_offset=0.0005, tip_to_bottom=0.0,
              wall_penetration=0.00027),
         "peg's section 0.27 mm into the hole's wall"),
        # Deep in a 0.5 mm hole and tilted more than its clearance allows (1.1 deg).
        (dict(tilt_error_deg=2.0, tip_depth=0.045, lateral_offset=0.0002, tip_to_bottom=0.0,
              wall_penetration=0.0),
         "peg tilted 2.0 deg from the hole axis"),
    ],
)  # fmt: skip
def test_a_failed_insertion_is_named_by_where_the_peg_ended(metrics, expected):
    from cfvs_maniskill.episode import failure_reason

    assert failure_reason(metrics, tilt_limit_deg=1.14) == expected


def test_the_readme_gets_a_table_for_the_other_cameras_where_it_has_its_markers():
    """The d435 and textured profiles fill their own table (`report:headline-cameras`), and
    a README without those markers gets only the main one."""
    from cfvs_maniskill.report.tables import fill_headlines

    recs = [
        {"label": "cfvs", "task": "PegInsert3DoF", "sensor": s, "init": i, "success": ok}
        | {"mount": "tip_view"}  # as report/load.py gives every record
        for s, ok in (("ideal", True), ("d435", False), ("textured", True))
        for i in ("small", "large")
    ]
    main = "<!-- report:headline begin -->\n<!-- report:headline end -->\n"
    cameras = "<!-- report:headline-cameras begin -->\n<!-- report:headline-cameras end -->\n"
    text = fill_headlines(main + cameras, recs, "README.md")
    first, second = text.split("<!-- report:headline-cameras begin -->")
    assert "| 3DoF ideal | 3DoF realistic |" in first and "d435" not in first
    assert "| cfvs | 1.00 / 1.00 | - / - | - / - |" in first
    assert "| 3DoF d435 | 3DoF textured |" in second
    assert "| cfvs | 0.00 / 0.00 | 1.00 / 1.00 | - / - |" in second
    assert fill_headlines(main, recs, "README.md").count("| cfvs |") == 1


def test_an_agent_on_another_mount_than_the_rest_is_named_with_it():
    """KOVIS's networks learnt one mount's images and run on it (`env_options`): the
    README's table says so beside its name; agents on the usual mount get no note."""
    from cfvs_maniskill.report.tables import table_headline

    recs = [
        {"label": a, "task": "PegInsert3DoF", "sensor": s, "init": i, "success": True,
         "mount": m if a == "kovis" else own}
        for a, m in (("cfvs", ""), ("icp", ""), ("kovis", "flange_side"))
        for s, own in (("ideal", "tip_view"), ("d435", "tip_view_long"))
        for i in ("small", "large")
    ]  # fmt: skip
    text = table_headline(recs, ("ideal", "d435"))
    assert "| cfvs | 1.00 / 1.00 |" in text and "| icp | 1.00 / 1.00 |" in text
    assert "| kovis (flange_side mount) | 1.00 / 1.00 |" in text


def test_table_iv_compares_the_ablations_under_the_papers_protocol():
    """Table IV reads the runs without the compliant search (labelled `_plain`), which
    would rescue what an ablated component leaves off; runs with it are not counted."""
    from cfvs_maniskill.report.tables import table_iv

    def rec(label: str, success: bool) -> dict:
        return {"label": label, "dof": 6, "success": success}

    records = [rec("cfvs_no_c2f_plain", s) for s in (True, False, False, False)]
    records += [rec("cfvs_no_c2f", True)] * 4 + [rec("cfvs_plain", True)] * 2
    rows = {line.split(" | ")[0].strip("| "): line for line in table_iv(records).splitlines()}
    assert "0.25" in rows["cfvs_no_c2f"] and "(n=4)" in rows["cfvs_no_c2f"]
    assert "1.00" in rows["cfvs"] and "(n=2)" in rows["cfvs"]


def test_a_record_on_a_mount_with_its_own_weights_is_checked_against_them():
    """`report --check` rebuilds the agent on the record's mount: a d435 record, made
    with the nets trained for `tip_view_long`, is current; one on `tip_view` is not."""
    from cfvs_maniskill.report.trace import agent_weights_today

    long = agent_weights_today("cfvs", "PegInsert3DoF", "tip_view_long")
    usual = agent_weights_today("cfvs", "PegInsert3DoF", "tip_view")
    assert "agents/cfvs/round/opnv.tip_view_long.pt" in long
    assert "agents/cfvs/round/opnv.pt" in usual and long != usual
    assert agent_weights_today("cfvs", "PegInsert3DoF", "my_bracket") == usual


def test_a_run_over_cameras_on_two_mounts_resumes_and_other_weights_are_named():
    """A folder holding d435 episodes (the `tip_view_long` mount, whose fine network is its
    own) beside ideal ones resumes: each record is judged against the weights the agent
    loads on its record's mount; a record made with other weights there is named."""
    from cfvs_maniskill import TASKS
    from cfvs_maniskill.eval.__main__ import unbuildable
    from cfvs_maniskill.eval.jobs import scene_seed
    from cfvs_maniskill.eval.settings import Settings, differences
    from cfvs_maniskill.report.trace import agent_weights_today
    from cfvs_maniskill.robots.mounts import MOUNTS

    task = "PegInsert3DoF"
    now = Settings(seed=0, search_radius=0.0)
    mounts = (MOUNTS["tip_view"], MOUNTS["tip_view_long"])
    assert unbuildable(["cfvs"], {task: TASKS[task]}, now.weights, mounts) == set()
    long, usual = (agent_weights_today("cfvs", task, m.name) for m in mounts[::-1])
    assert long != usual and now.weights[(task, "cfvs", "tip_view_long")] == long
    assert now.weights[(task, "cfvs", "tip_view")] == usual  # from the build that decided

    def record(sensor: str, mount: str, weights: dict) -> tuple[str, dict]:
        key = f"{task}|cfvs|cylinder|large|0|{sensor}"
        seed = scene_seed(task, "cylinder", "large", 0, 0)
        return key, {"seed": seed, "mount": mount, "provenance": {"weights": weights}}

    done = dict([record("ideal", "tip_view", usual), record("d435", "tip_view_long", long)])
    assert differences(done, now) == []
    done = dict([record("d435", "tip_view_long", usual)])
    (why,) = differences(done, now)
    assert "agent cfvs on PegInsert3DoF: its weights" in why and "tip_view_long" in why


def test_rerun_stale_runs_only_the_stale_records_again_and_never_a_frozen_sets(tmp_path):
    """--rerun-stale on two of the README's oracle records, one of them made stale (another
    episode code, uncommitted): that one leaves the folder and runs again, the other stays
    as it was, and so does a stale record of an agent the command does not run. On a frozen
    set's results it is refused before anything is written."""
    import gzip

    src = ROOT / "results/headline/main/episodes.jsonl.gz"
    keys = [f"PegInsert3DoF|oracle|cuboid_test_1|small|{e}" for e in (0, 1)]  # ideal: no suffix
    lines = gzip.decompress(src.read_bytes()).decode().splitlines()
    mine = [r for r in map(json.loads, lines) if r["key"] in keys]
    assert len(mine) == 2, [r["key"] for r in mine]
    current, old = sorted(mine, key=lambda r: r["key"])
    stale = {"code": "v0+dirty", "code_fingerprint": "0"}
    old = {**old, "provenance": {**old["provenance"], **stale}}
    other = {**old, "agent": "icp", "key": old["key"].replace("oracle", "icp")}
    gz = tmp_path / "episodes.jsonl.gz"
    text = "".join(json.dumps(r) + "\n" for r in (current, old, other))
    gz.write_bytes(gzip.compress(text.encode()))
    args = ["--tasks", "PegInsert3DoF", "--agents", "oracle", "--objects", "cuboid_test_1",
            "--init-errors", "small", "--episodes-per-object", "2", "--seed", "0",
            "--workers", "1", "--rerun-stale"]  # fmt: skip
    r = run_cli("cfvs_maniskill.eval", *args, "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr[-2000:]
    assert "1 stale records removed" in r.stdout and "1 to run" in r.stdout, r.stdout
    assert "stale: episode code changed since v0+dirty (1 records)" in r.stdout
    lines = gzip.decompress(gz.read_bytes()).decode().splitlines()
    assert len(lines) == 3 and not (tmp_path / "episodes.jsonl").exists()  # folded, no twins
    recs = {x["key"]: x for x in map(json.loads, lines)}
    assert set(recs) == {current["key"], old["key"], other["key"]}
    assert recs[current["key"]] == current and recs[other["key"]] == other
    assert recs[old["key"]]["provenance"]["code"] != "v0+dirty"
    assert recs[old["key"]]["seed"] == old["seed"]

    held = ROOT / "results/generalisation_housings/1.2.0/search-0"
    before = sorted(p.name for p in held.iterdir())
    r = run_cli("cfvs_maniskill.eval", *args, "--out", str(held))
    assert r.returncode == 2 and "frozen set's records" in r.stderr, r.stderr[-2000:]
    assert sorted(p.name for p in held.iterdir()) == before
