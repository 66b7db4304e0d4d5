"""The run command, as a user types it."""

from __future__ import annotations

import json
import re

import imageio_ffmpeg

from .conftest import quiet, run_cli


def test_run_writes_json_lines_and_a_summary(tmp_path):
    out = tmp_path / "r.jsonl"
    r = run_cli(
        "cfvs_maniskill.run",
        "--task",
        "PegInsert3DoF",
        "--agent",
        "oracle",
        "--episodes",
        "2",
        "--seed",
        "7",
        "--out",
        str(out),
    )
    assert r.returncode == 0, r.stderr[-2000:]
    assert "success 2/2" in r.stdout and "95% CI" in r.stdout
    assert quiet(r.stderr), r.stderr[-2000:]  # the renderer's start-up lines go nowhere
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    assert [row["seed"] for row in rows] == [7, 8]
    for row in rows:
        for key in (
            "task",
            "agent",
            "object",
            "seed",
            "init_error_m",
            "success",
            "servo_time_s",
            "steps",
            "reason",
        ):
            assert key in row
        assert (
            row["success"] is True and row["agent"] == "oracle" and row["task"] == "PegInsert3DoF"
        )


def test_bad_names_exit_2_listing_valid_ones():
    r = run_cli("cfvs_maniskill.run", "--task", "PegInsert7DoF")
    assert r.returncode == 2 and "PegInsert6DoF" in r.stderr and "Traceback" not in r.stderr
    r = run_cli("cfvs_maniskill.run", "--agent", "telepathy")
    assert r.returncode == 2 and "oracle" in r.stderr and "Traceback" not in r.stderr
    r = run_cli("cfvs_maniskill.run", "--objects", "teapot")
    assert r.returncode == 2 and "cuboid_test_1" in r.stderr and "Traceback" not in r.stderr


def test_video_is_a_playable_mp4(tmp_path):
    r = run_cli(
        "cfvs_maniskill.run",
        "--task",
        "PegInsert6DoF-v1",
        "--episodes",
        "1",
        "--video",
        str(tmp_path),
    )
    assert r.returncode == 0, r.stderr[-2000:]
    videos = list(tmp_path.glob("*.mp4"))
    assert len(videos) == 1
    import subprocess

    probe = subprocess.run(
        [imageio_ffmpeg.get_ffmpeg_exe(), "-i", str(videos[0]), "-f", "null", "-"],
        capture_output=True,
        text=True,
    )
    frames = [int(n) for n in re.findall(r"frame=\s*(\d+)", probe.stderr)]
    assert frames and frames[-1] > 20
    w, h = map(int, re.search(r", (\d{3,})x(\d{3,})", probe.stderr).groups())
    assert h >= 512 and w > h  # the close view beside the overview and the wrist view
