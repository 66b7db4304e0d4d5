"""Datasets: labels checked geometrically on real rendered samples, augmentation,
crash-safe resumable files, the picture."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch

from cfvs_maniskill import geometry as G
from cfvs_maniskill.constants import MIN_WALL, PRE_INSERT_HEIGHT
from cfvs_maniskill.data.augment import AugmentConfig, augment
from cfvs_maniskill.data.collect import CollectArgs, collect
from cfvs_maniskill.data.procedural import procedural_specs
from cfvs_maniskill.data.store import DatasetError, load
from cfvs_maniskill.objects.library import load_library
from cfvs_maniskill.perception import labels as L
from cfvs_maniskill.perception.clouds import tool_to_world

from .conftest import ROOT, run_cli


@pytest.fixture(scope="module")
def coarse_file(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("data") / "coarse.h5"
    collect(CollectArgs(task="PegInsert6DoF", kind="coarse", samples=12, out=out, points=512))
    return out


@pytest.fixture(scope="module")
def fine_file(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("data") / "fine.h5"
    collect(CollectArgs(task="PegInsert6DoF", kind="fine", samples=12, out=out, points=512))
    return out


def test_coarse_labels_are_geometrically_right(coarse_file):
    attrs, d = load(coarse_file)
    assert attrs["kind"] == "coarse" and d["points"].shape == (12, 512, 3)
    # Offsets + points give the keypoints exactly.
    recon = d["points"][:, :, None, :] + d["offsets"]
    assert np.abs(recon - d["keypoints"][:, None]).max() < 1e-6
    for i in range(12):
        tcp, H = d["tcp_pose"][i], d["hole_pose"][i]
        k = tool_to_world(d["keypoints"][i].astype(np.float64), tcp)
        # k1 is the hole's centre on its top face; k3 is on the hole axis, out of the hole.
        assert np.linalg.norm(k[0] - H[:3, 3]) < 1e-5
        kh = (k - H[:3, 3]) @ H[:3, :3]  # keypoints in the hole frame
        assert np.allclose(kh[2], [0, 0, L.KEYPOINT_SPACING], atol=1e-5)
        assert abs(kh[1, 2]) < 1e-5 and abs(np.linalg.norm(kh[1]) - L.KEYPOINT_SPACING) < 1e-5
        # The top face really is there: object points within 2-4 cm of k1 lie at z ~ 0.
        p = (tool_to_world(d["points"][i].astype(np.float64), tcp) - H[:3, 3]) @ H[:3, :3]
        r = np.hypot(p[:, 0], p[:, 1])
        ring = (r > 0.037) & (r < 0.05)
        assert ring.sum() > 5 and np.median(np.abs(p[ring, 2])) < 0.003
        # The highest-confidence points surround the hole: close to its axis, all around.
        c = d["confidence"][i]
        top = np.argsort(c)[-40:]
        assert np.median(r[top]) < 0.045
        sectors = np.histogram(np.arctan2(p[top, 1], p[top, 0]), bins=4, range=(-np.pi, np.pi))
        assert (sectors[0] > 0).sum() >= 3, sectors[0]
        assert np.allclose(
            c, np.exp(-np.sum(p**2, axis=1) / (2 * L.CONFIDENCE_SIGMA**2)), atol=1e-4
        )


def test_fine_actions_undo_the_perturbation(fine_file, make_env):
    attrs, d = load(fine_file)
    assert attrs["kind"] == "fine" and d["action"].shape == (12, 6)
    env = make_env("PegInsert6DoF-v1", obs_mode="state", objects=("train",))
    u = env.unwrapped
    moved = 0
    for i in range(12):
        tcp, H, a = d["tcp_pose"][i], d["hole_pose"][i], d["action"][i].astype(np.float64)
        assert np.linalg.norm(a[:3]) <= 0.0301 and np.degrees(np.linalg.norm(a[3:])) < 47
        T = L.apply_action(tcp, a)
        # Applying the action reaches the true pre-insertion pose above the hole ...
        tip = G.inv(H) @ T
        assert np.allclose(tip[:3, 3], [0, 0, PRE_INSERT_HEIGHT], atol=1e-4)
        assert np.degrees(np.arccos(np.clip(-tip[2, 2], -1, 1))) < 0.05
        # ... and the robot really gets there.
        q, ok = u.ik(T, u.agent.robot.get_qpos()[0].numpy())
        if ok:
            u.agent.reset(torch.as_tensor(q, dtype=torch.float32)[None])
            assert np.linalg.norm(u.tcp_matrix()[:3, 3] - T[:3, 3]) < 1e-3
            moved += 1
    assert moved >= 10


def test_augmentation_keeps_the_hole_and_changes_the_body(coarse_file):
    _, d = load(coarse_file, ("points", "keypoints"))
    p, k = d["points"][0], d["keypoints"][0]
    H = L.hole_frame_from_keypoints(k.astype(np.float64))
    u = (p - H[:3, 3]) @ H[:3, :3]
    near = np.hypot(u[:, 0], u[:, 1]) < AugmentConfig().keep_radius
    rng = np.random.default_rng(0)
    kinds = set()
    for _ in range(40):
        q, kind = augment(p, k, rng, AugmentConfig())
        kinds.add(kind)
        assert q.shape == p.shape and np.isfinite(q).all()
        assert np.abs(q[near] - p[near]).max() < 1e-5  # the hole region is untouched
        if kind != "none":
            assert np.abs(q[~near] - p[~near]).max() > 1e-3
    assert kinds == {"none", "scale", "rotate", "mix"}


def test_procedural_bodies_are_valid_training_objects(tmp_path, monkeypatch):
    monkeypatch.setenv("CFVS_CACHE", str(tmp_path))
    folder, names = procedural_specs(8, seed=3, peg="square", clearance=0.004, depth=0.045)
    lib = load_library([folder])
    assert not lib.errors
    specs = [lib.specs[n] for n in names]
    assert all(s.split == "train" for s in specs)
    assert len({(s.body_kind, str(s.body)) for s in specs}) == 8
    assert {s.name for s in lib.select(["test"])}.isdisjoint(names)


def _mesh_bodies(count: int, seed: int, peg: str, **family):
    """Write `count` procedural mesh bodies of a family (4 mm clearance, 45 mm deep), check
    each is a valid, buildable training object with a hole frame: (folder, names,
    [(spec, mesh)])."""
    import trimesh

    from cfvs_maniskill.objects.build import build_geometry

    folder, names = procedural_specs(count, seed, peg, 0.004, 0.045, **family)
    lib = load_library([folder])
    assert not lib.errors
    built = []
    for n in names:
        spec = lib.specs[n]
        assert spec.split == "train" and spec.body_kind == "mesh" and spec.hole_frame
        build_geometry(spec, peg, 0.004, 0.045)  # room for the hole, collision parts
        built.append((spec, trimesh.load(folder / spec.body["file"])))
    return folder, names, built


def test_featured_procedural_bodies_put_a_block_or_notch_beside_the_hole(tmp_path, monkeypatch):
    """`--procedural-features`: mesh bodies whose top is not one flat face around the hole
    (a raised block or a notch within a few cm of the rim), every one a valid, buildable
    training object, the same files for the same seed."""
    monkeypatch.setenv("CFVS_CACHE", str(tmp_path))
    shown = 0
    folder, names, built = _mesh_bodies(6, 5, "round", family="features")
    for spec, body in built:
        top, z = spec.hole_frame[0][2], body.vertices[:, 2]
        raised = z.max() > top + 0.005
        stepped = ((z > 0.001) & (z < top - 0.005)).any()
        notched = body.convex_hull.volume > 1.01 * body.volume  # an L: concave outline
        shown += bool(raised or stepped or notched)
    # The rest are straight cuts: an edge near the hole, convex, not told apart from a
    # smaller primitive here.
    assert shown >= 4, f"only {shown} of 6 bodies have a block, a step or an inner corner"
    first = (folder / f"{names[0]}.yaml").read_text()
    monkeypatch.setenv("CFVS_CACHE", str(tmp_path / "again"))
    folder2, _ = procedural_specs(6, 5, "round", 0.004, 0.045, "features")
    assert (folder2 / f"{names[0]}.yaml").read_text() == first


def test_part_like_procedural_bodies_are_tall_with_inclined_faces_around_the_hole(
    tmp_path, monkeypatch
):
    """`--procedural-parts`: bodies 10-26 cm tall whose opening sits on what is left of the
    top face, with inclined planar faces (neither flat nor vertical) falling away from it,
    every one a valid, buildable training object."""
    from cfvs_maniskill.data.procedural import PART_HEIGHT

    monkeypatch.setenv("CFVS_CACHE", str(tmp_path))
    inclined = 0
    for spec, body in _mesh_bodies(4, 7, "square", family="parts")[2]:
        top = spec.hole_frame[0][2]
        assert PART_HEIGHT[0] <= top <= PART_HEIGHT[1] + 1e-6
        assert body.bounds[1, 2] == pytest.approx(top, abs=1e-6)  # nothing above the opening
        nz = np.abs(body.face_normals[:, 2])
        slanted = body.area_faces[(nz > 0.3) & (nz < 0.97)].sum()
        inclined += slanted > 1e-3  # at least 10 cm^2 of inclined face
    assert inclined >= 3, f"only {inclined} of 4 bodies have an inclined face"
    both = CollectArgs(
        procedural=True, procedural_features=True, procedural_parts=True, out=tmp_path / "x.h5"
    )
    with pytest.raises(DatasetError, match="--procedural-family: expected one body family"):
        collect(both)
    assert not (tmp_path / "x.h5").exists()


@pytest.mark.slow
def test_resume_after_kill_gives_exactly_n_unique_samples(tmp_path):
    """SIGKILL a collection after its first chunk, run it again: N samples, each once,
    identical to an uninterrupted collection."""
    # 20 samples: two chunks of 10, the kill lands in the second.
    args = ["--task", "PegInsert3DoF", "--kind", "coarse", "--samples", "20", "--chunk", "10"]
    args += ["--points", "256"]
    out = tmp_path / "killed.h5"
    cmd = [sys.executable, "-m", "cfvs_maniskill.data", "collect", *args, "--out", str(out)]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    parts = Path(str(out) + ".parts")
    deadline = time.time() + 300
    while not list(parts.glob("part-*.npz")) and time.time() < deadline:
        time.sleep(0.2)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert list(parts.glob("part-*.npz")), "no chunk was written before the kill"
    assert not out.exists()
    r = run_cli("cfvs_maniskill.data", "collect", *args, "--out", str(out))
    assert r.returncode == 0, r.stderr[-2000:]
    ref = tmp_path / "ref.h5"
    r = run_cli("cfvs_maniskill.data", "collect", *args, "--out", str(ref))
    assert r.returncode == 0, r.stderr[-2000:]
    with h5py.File(out) as a, h5py.File(ref) as b:
        assert np.array_equal(a["sample_index"][:], np.arange(20))
        pa = a["points"][:]
        assert len(np.unique(pa.reshape(20, -1), axis=0)) == 20
        assert np.array_equal(pa, b["points"][:])
        assert list(a["object"].asstr()[:]) == list(b["object"].asstr()[:])
    assert not parts.exists()


def test_mismatched_resume_names_the_field(coarse_file):
    with pytest.raises(DatasetError, match="field 'kind'"):
        collect(CollectArgs(task="PegInsert6DoF", kind="fine", samples=20, out=coarse_file))
    with pytest.raises(DatasetError, match="field 'num_points'"):
        collect(CollectArgs(task="PegInsert6DoF", kind="coarse", samples=20, out=coarse_file))
    with pytest.raises(DatasetError, match="--chunk: expected a positive number"):
        collect(CollectArgs(task="PegInsert6DoF", kind="coarse", chunk=0, out=coarse_file))


def test_show_draws_a_png(coarse_file, fine_file, tmp_path):
    from cfvs_maniskill.data.show import show

    for f in (coarse_file, fine_file):
        png = show(f, 1, tmp_path / f"{f.stem}.png")
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000
    r = run_cli("cfvs_maniskill.data", "show", str(coarse_file), "--index", "99")
    assert r.returncode == 2 and "--index" in r.stderr and "12 samples" in r.stderr


@pytest.fixture(scope="module")
def kovis_file(tmp_path_factory):
    out = tmp_path_factory.mktemp("kovis") / "kovis.h5"
    collect(CollectArgs(task="PegInsert4DoF", kind="kovis", samples=12, out=out))
    return out


def test_kovis_rollouts_are_stereo_pairs_with_the_motion_to_the_goal(kovis_file):
    """A KOVIS sample is a rollout from the goal: 5 frames of the wrist camera's two lit
    imagers (different views of one scene), their depth and segmentation, and the tool
    motion that returns each frame's pose to the goal (zero at the first frame)."""
    attrs, d = load(kovis_file)
    assert attrs["kind"] == "kovis"
    assert d["images"].shape == (12, 5, 2, 96, 96) and d["images"].dtype == np.uint8
    assert d["depth"].shape == d["seg"].shape == (12, 5, 2, 48, 48)
    assert d["images"].std() > 5  # real images, not blanks
    left, right = d["images"][:, :, 0].astype(float), d["images"][:, :, 1].astype(float)
    assert 0.5 < np.abs(left - right).mean() < 40  # two imagers apart, one scene
    assert set(np.unique(d["seg"])) >= {0, 2}  # background and the hole object
    assert np.all(d["valid"][:, :3])  # at least 3 frames per rollout, as KOVIS keeps
    assert np.allclose(d["twist"][:, 0], 0, atol=1e-3)  # the first frame is the goal
    for r in range(12):
        for k in np.nonzero(d["valid"][r])[0]:
            tcp, a = d["tcp_pose"][r, k], d["twist"][r, k]
            assert np.allclose(L.apply_action(tcp, a), d["target_pose"][r], atol=1e-4)
            assert tcp[2, 2] < -0.999  # 4-DoF: the peg points straight down
            assert np.allclose(a[3:5], 0, atol=1e-4)  # 4-DoF: yaw is the only rotation


def test_kovis_training_resumes_where_it_stopped(kovis_file, tmp_path):
    """Stopped by --max-minutes after its first batch and run again, KOVIS training ends in
    the same weights as one uninterrupted run (same batches, same augmentation draws)."""
    from cfvs_maniskill.policies.kovis.train import TrainKOVISArgs
    from cfvs_maniskill.policies.kovis.train import train as train_kovis
    from cfvs_maniskill.policies.networks import load_weights

    def args(out, minutes=0.0):
        return TrainKOVISArgs(
            data=(kovis_file,), out=out, dof=4, epochs=2, batch=8, growth=(4, 4, 16),
            val_fraction=0.2, max_minutes=minutes, threads=1,
        )  # fmt: skip

    whole = tmp_path / "whole.pt"
    train_kovis(args(whole))
    split = tmp_path / "split.pt"
    state = train_kovis(args(split, minutes=1e-6))
    resume = split.with_name(split.name + ".resume")
    assert not split.exists() and resume.exists() and state["step"] == 1
    train_kovis(args(split))
    assert not resume.exists()
    a, _ = load_weights(whole, "kovis", "square")
    b, meta = load_weights(split, "kovis", "square")
    for (k, x), y in zip(a.state_dict().items(), b.state_dict().values(), strict=True):
        assert torch.equal(x, y), k
    assert len(meta["history"]) == 2


def test_training_writes_weights_that_load(coarse_file, kovis_file, tmp_path):
    """Both training commands end in a weights file that the agents' loader accepts, with
    its command and metrics beside it."""
    from cfvs_maniskill.policies.cfvs.train import TrainArgs
    from cfvs_maniskill.policies.cfvs.train import train as train_cfvs
    from cfvs_maniskill.policies.kovis.train import TrainKOVISArgs
    from cfvs_maniskill.policies.kovis.train import train as train_kovis
    from cfvs_maniskill.policies.networks import load_weights

    out = tmp_path / "oakn.pt"
    train_cfvs(TrainArgs(net="oakn", data=(coarse_file,), out=out, epochs=1, batch=4, points=128))
    _, meta = load_weights(out, "oakn", "square")
    assert meta["command"].startswith("python -m cfvs_maniskill.policies.cfvs.train")
    assert out.with_suffix(".json").is_file()
    out = tmp_path / "square.pt"
    train_kovis(
        TrainKOVISArgs(data=(kovis_file,), out=out, dof=4, epochs=1, batch=4, growth=(4, 4, 16))
    )
    net, meta = load_weights(out, "kovis", "square")
    assert net.cfg.motion_dims == 4 and "direction_err_deg_mean" in meta["validation"]


def test_training_on_several_files_holds_out_each_and_records_them(coarse_file, tmp_path):
    """`train --data A B`: one set, each file's tail in validation, every file recorded;
    files for another peg are refused naming the file and the field."""
    from cfvs_maniskill.data.store import load_sets
    from cfvs_maniskill.nets.checkpoint import file_sha256
    from cfvs_maniskill.policies.cfvs.train import TrainArgs
    from cfvs_maniskill.policies.cfvs.train import train as train_cfvs
    from cfvs_maniskill.policies.networks import load_weights

    other = tmp_path / "other.h5"
    shutil.copy(coarse_file, other)
    sets = load_sets((coarse_file, other), ("points",), "coarse", "oakn")
    m = len(load(coarse_file, ("points",))[1]["points"])
    assert len(sets.data["points"]) == 2 * m
    assert (sets.val_idx < m).any() and (sets.val_idx >= m).any()
    assert not set(sets.val_idx) & set(sets.train_idx)
    out = tmp_path / "oakn.pt"
    train_cfvs(
        TrainArgs(net="oakn", data=(coarse_file, other), out=out, epochs=1, batch=4, points=128)
    )
    _, meta = load_weights(out, "oakn", "square")
    assert [f["path"] for f in meta["data_files"]] == [str(coarse_file), str(other)]
    assert meta["data_sha256"] == [file_sha256(coarse_file), file_sha256(other)]
    assert meta["data_samples"] == 2 * m
    with h5py.File(other, "a") as f:
        f.attrs["peg"] = "round"
    with pytest.raises(DatasetError, match=r"other\.h5: field 'peg'"):
        load_sets((coarse_file, other), ("points",), "coarse", "oakn")


def test_training_from_init_weights_starts_where_they_end(coarse_file, tmp_path, capsys):
    """`train --init W`: the run starts from W's weights (zero epochs of change at lr 0 leave
    them as they were), is recorded, and a file of another net kind exits 2 naming it."""
    from cfvs_maniskill.policies.cfvs.train import TrainArgs, main
    from cfvs_maniskill.policies.cfvs.train import train as train_cfvs
    from cfvs_maniskill.policies.networks import load_weights

    first = tmp_path / "first.pt"
    train_cfvs(TrainArgs(net="oakn", data=(coarse_file,), out=first, epochs=1, batch=4, points=128))
    again = tmp_path / "again.pt"
    args = TrainArgs(
        net="oakn",
        data=(coarse_file,),
        out=again,
        epochs=1,
        batch=4,
        points=128,
        lr=0.0,
        weight_decay=0.0,
        init=first,
    )
    train_cfvs(args)
    a, _ = load_weights(first, "oakn")
    b, meta = load_weights(again, "oakn")
    for (k, x), y in zip(a.state_dict().items(), b.state_dict().values(), strict=True):
        if x.dtype.is_floating_point and "running" not in k and "num_batches" not in k:
            assert torch.equal(x, y), k
    assert meta["init"]["path"] == str(first)
    bad = ["--net", "oakn", "--data", str(coarse_file), "--out", str(tmp_path / "x.pt")]
    assert main([*bad, "--init", str(tmp_path / "nosuch.pt")]) == 2
    assert "nosuch.pt: weights file not found" in capsys.readouterr().err


def test_kovis_training_from_init_takes_encoder_and_the_fitting_converter(kovis_file, tmp_path):
    """`train_kovis --init W`: at lr 0 the run ends in W's weights (recorded with its hash);
    a converter for another --dof is left fresh while encoder and decoder are taken; an
    encoder of another growth is refused naming the field."""
    from cfvs_maniskill.nets.checkpoint import WeightsError, file_sha256
    from cfvs_maniskill.policies.kovis.train import TrainKOVISArgs
    from cfvs_maniskill.policies.kovis.train import train as train_kovis
    from cfvs_maniskill.policies.networks import load_weights

    def args(out, **kw):
        base = dict(data=(kovis_file,), out=out, epochs=1, batch=8, growth=(4, 4, 16), dof=4)
        return TrainKOVISArgs(**{**base, **kw}, val_fraction=0.2, threads=1)

    first = tmp_path / "first.pt"
    train_kovis(args(first))
    again = tmp_path / "again.pt"
    train_kovis(args(again, init=first, lr=0.0, weight_decay=0.0))
    a, _ = load_weights(first, "kovis")
    b, meta = load_weights(again, "kovis")
    for (k, x), y in zip(a.state_dict().items(), b.state_dict().values(), strict=True):
        if x.dtype.is_floating_point and "running" not in k:
            assert torch.equal(x, y), k
    assert meta["init"]["path"] == str(first) and meta["init"]["sha256"] == file_sha256(first)
    six = tmp_path / "six.pt"
    train_kovis(args(six, init=first, lr=0.0, weight_decay=0.0, dof=6))
    c, meta = load_weights(six, "kovis")
    assert meta["init"]["parts"] == ["encoder", "decoder"]
    assert torch.equal(c.encoder.state_dict()["head.weight"], a.encoder.state_dict()["head.weight"])
    with pytest.raises(WeightsError, match=r"first\.pt: field 'growth'"):
        train_kovis(args(tmp_path / "x.pt", init=first, growth=(6, 6, 16)))


def test_kovis_rollout_step_range_is_kept_and_checked(tmp_path):
    """`collect --kind kovis --rollout-step MIN MAX`: every rollout's step lies in the range
    (frame k is k steps from the goal), the file records it, a resume with another range
    and an empty range are refused naming the field."""
    out = tmp_path / "far.h5"
    collect(CollectArgs(task="PegInsert3DoF", kind="kovis", samples=3, out=out,
                        rollout_step=(0.03, 0.05)))  # fmt: skip
    attrs, d = load(out)
    assert attrs["rollout_step"] == "[0.03, 0.05]"
    for r in range(3):
        n = int(d["valid"][r].sum())
        dist = np.linalg.norm(d["twist"][r, 1:n, :3], axis=-1) / np.arange(1, n)
        assert np.all((dist > 0.03 - 1e-4) & (dist < 0.05 + 1e-4)), dist
    with pytest.raises(DatasetError, match="field 'rollout_step'"):
        collect(CollectArgs(task="PegInsert3DoF", kind="kovis", samples=4, out=out))
    with pytest.raises(DatasetError, match="--rollout-step"):
        collect(CollectArgs(task="PegInsert3DoF", kind="kovis", samples=4, out=out,
                            rollout_step=(0.05, 0.03)))  # fmt: skip


def test_ribbed_pocketed_and_narrow_families_and_the_held_out_one(tmp_path, monkeypatch):
    """The wider generator: ribs stand above the opening's face, pockets and counterbores
    make the top concave, narrow bodies leave little more than the hole's walls; each body
    is a valid, buildable training object. The held-out family never goes into training."""
    from cfvs_maniskill.data.procedural import TRAINING_FAMILIES
    from cfvs_maniskill.data.shapes import keep_clear

    monkeypatch.setenv("CFVS_CACHE", str(tmp_path))
    keep = keep_clear("square", 0.004)
    for spec, body in _mesh_bodies(3, 11, "square", family="ribs")[2]:
        assert body.vertices[:, 2].max() > spec.hole_frame[0][2] + 0.004
    for _spec, body in _mesh_bodies(3, 11, "square", family="pockets")[2]:
        assert body.convex_hull.volume > body.volume + 1e-7  # a pocket, a bore or a recess
    for _spec, body in _mesh_bodies(3, 11, "square", family="narrow")[2]:
        extent = body.bounds[1] - body.bounds[0]
        assert extent[:2].min() <= 2 * keep + 0.016 and extent[2] >= 0.08
    assert "composite" not in TRAINING_FAMILIES
    with pytest.raises(ValueError, match="held out of training"):
        procedural_specs(2, 1, "square", 0.004, 0.045, "composite")
    args = CollectArgs(procedural=True, procedural_family="composite", out=tmp_path / "c.h5")
    with pytest.raises(DatasetError, match="--procedural-family: expected one of .*held out"):
        collect(args)
    assert not (tmp_path / "c.h5").exists()


def test_grooved_family_cuts_grooves_beside_the_hole_and_is_held_out(tmp_path, monkeypatch):
    """`grooved` (the successor frozen set's family): V-grooves and slots 3-15 mm deep cut
    across the face outside the hole's wall, a valid and buildable test object; training
    never draws it."""
    import trimesh

    from cfvs_maniskill.data.procedural import TRAINING_FAMILIES
    from cfvs_maniskill.data.shapes import keep_clear
    from cfvs_maniskill.objects.build import build_geometry

    monkeypatch.setenv("CFVS_CACHE", str(tmp_path))
    keep = keep_clear("square", 0.004)
    folder, names = procedural_specs(
        2, 5, "square", 0.004, 0.045, "grooved", split="test", folder=tmp_path / "g"
    )
    lib = load_library([folder])
    assert not lib.errors
    for n in names:
        spec = lib.specs[n]
        assert spec.split == "test" and spec.body_kind == "mesh"
        body = trimesh.load(folder / spec.body["file"])
        hole, top = np.array(spec.hole_frame[0][:2]), spec.hole_frame[0][2]
        v = body.vertices
        beside = np.linalg.norm(v[:, :2] - hole, axis=1) > keep
        floor = beside & (v[:, 2] < top - 0.0029) & (v[:, 2] > top - 0.0151)
        assert floor.any() and body.convex_hull.volume > body.volume + 1e-7, n
    build_geometry(lib.specs[names[0]], "square", 0.004, 0.045)  # room for the hole
    assert "grooved" not in TRAINING_FAMILIES
    with pytest.raises(ValueError, match="held out of training"):
        procedural_specs(2, 1, "square", 0.004, 0.045, "grooved")


def test_fixture_features_stand_where_they_say_and_the_family_is_held_out(tmp_path):
    """`fixtures` (release 1.1.0's frozen set): a bolt circle drills evenly spaced holes
    round the opening, pins stand on the face and never off its edge, a ramp's face slopes;
    none touches the opening's wall, and training never draws the family."""
    import trimesh

    from cfvs_maniskill.data import shapes as S
    from cfvs_maniskill.data.procedural import TRAINING_FAMILIES

    keep, top = S.keep_clear("square", 0.004), 0.05
    plate = S.box_at([0.2, 0.2, top], [0, 0, top / 2])
    hole = np.array([0.085, 0.0])  # near an edge: pins beyond it would float
    for seed in range(4):
        rng = np.random.default_rng(seed)
        drilled, _ = S.add_bolt_circle(rng, plate, hole, top, keep)
        drill = np.pi * (0.3 * (keep - MIN_WALL)) ** 2 * 0.01  # the smallest hole's volume
        assert drilled.volume < plate.volume - 2 * drill, seed  # a half circle at least
        pinned, _ = S.add_pins(np.random.default_rng(seed), plate, hole, top, keep)
        tall = pinned.vertices[pinned.vertices[:, 2] > top + 0.01]
        assert len(tall) and np.all(np.abs(tall[:, :2]) <= 0.1 + 1e-6), seed  # on the face
        ramp, _ = S.add_ramp(np.random.default_rng(seed), plate, hole, top, keep)
        n = ramp.face_normals
        assert np.any((np.abs(n[:, 2]) > 0.2) & (np.abs(n[:, 2]) < 0.995)), seed  # a slope
        for body in (drilled, pinned, ramp):
            near = np.linalg.norm(body.vertices[:, :2] - hole, axis=1) < keep
            assert not near.any(), seed  # the opening's wall stays whole
    for seed in (1, 9):  # these draw an island before pins, a wall: they stand on the face
        drawn = S.fixture_body(np.random.default_rng(seed), "square", 0.004, tmp_path, "f")
        assert drawn is not None, seed
        body = trimesh.load(tmp_path / "f.stl")
        assert len(body.split(only_watertight=False)) == 1, seed
    assert "fixtures" not in TRAINING_FAMILIES
    with pytest.raises(ValueError, match="held out of training"):
        procedural_specs(2, 1, "square", 0.004, 0.045, "fixtures")


def plate_with_opening():
    """(keep, top, plate, hole) for adding features to: a 30 cm plate 5 cm thick, the square
    peg's opening (4 mm clearance) off its centre."""
    from cfvs_maniskill.data import shapes as S

    keep, top = S.keep_clear("square", 0.004), 0.05
    return keep, top, S.box_at([0.3, 0.3, top], [0, 0, top / 2]), np.array([0.03, -0.02])


def assert_wall_ring_at(body, hole, keep, level, seed, samples: int, more_than: int) -> None:
    """The opening's wall stays whole: of `samples` surface points of `body`, those within
    `keep` of the axis at `hole` (x, y) and above the table, more than `more_than`, all lie
    on the face at `level`."""
    import trimesh

    v, _ = trimesh.sample.sample_surface(body, samples, seed=seed)
    ring = (np.linalg.norm(v[:, :2] - hole, axis=1) < keep) & (v[:, 2] > 1e-4)
    assert ring.sum() > more_than and np.all(np.abs(v[ring, 2] - level) < 1e-6), seed


def assert_drawn_whole_and_held_out(family: str, tmp_path, at_least: int) -> None:
    """Of six draws of a frozen set's `family`, at least `at_least` give a body, each one
    watertight piece; training refuses the family."""
    import trimesh

    from cfvs_maniskill.data import shapes as S
    from cfvs_maniskill.data.procedural import TRAINING_FAMILIES

    draw = S.FAMILIES[family]
    drawn = [draw(np.random.default_rng(s), "square", 0.004, tmp_path, f"b{s}") for s in range(6)]
    assert sum(d is not None for d in drawn) >= at_least
    for s, d in enumerate(drawn):
        if d is not None:
            body = trimesh.load(tmp_path / f"b{s}.stl")
            assert body.is_watertight and len(body.split(only_watertight=False)) == 1, s
    assert family not in TRAINING_FAMILIES
    with pytest.raises(ValueError, match="held out of training"):
        procedural_specs(2, 1, "square", 0.004, 0.045, family)


def test_housing_features_stand_where_they_say_and_the_family_is_held_out(tmp_path):
    """`housings` (release 1.2.0's frozen set): a countersink slopes round the opening and
    puts the frame where the cone meets it, a tower lifts the opening 4-12 cm, a slot and a
    bracket keep off the opening's wall; training never draws the family."""

    from cfvs_maniskill.data import shapes as S

    keep, top, plate, hole = plate_with_opening()
    for seed in range(4):
        sunk, level = S.add_countersink(np.random.default_rng(seed), plate, hole, top, keep)
        assert top - 0.0075 < level < top - 0.0009, seed  # 1-4 mm flare at 30-45 deg
        assert sunk.volume < plate.volume, seed
        n, at = sunk.face_normals, sunk.triangles_center
        near = np.linalg.norm(at[:, :2] - hole, axis=1) < keep
        assert np.any(near & (np.abs(n[:, 2]) > 0.5) & (np.abs(n[:, 2]) < 0.9)), seed  # a cone
        tower, raised = S.add_tower(np.random.default_rng(seed), plate, hole, top, keep)
        assert 0.04 <= raised - top <= 0.12 and tower.bounds[1, 2] == pytest.approx(raised)
        slot, _ = S.add_slot(np.random.default_rng(seed), plate, hole, top, keep)
        bracket, _ = S.add_bracket(np.random.default_rng(seed), plate, hole, top, keep)
        assert slot.volume < plate.volume < bracket.volume, seed
        n = bracket.face_normals
        assert np.any((np.abs(n[:, 2]) > 0.2) & (np.abs(n[:, 2]) < 0.995)), seed  # gussets
        for body in (slot, bracket):  # nothing over or cut into the opening's wall
            assert_wall_ring_at(body, hole, keep, top, seed, samples=20000, more_than=100)
    assert_drawn_whole_and_held_out("housings", tmp_path, at_least=4)


def test_manifold_features_stand_where_they_say_and_the_family_is_held_out(tmp_path):
    """`manifolds` (release 1.3.0's frozen set): a seal groove, ports, a recess and fittings
    keep off the opening's wall (the recess lowers the face round it), a round bar keeps a
    flat land round the opening; training never draws the family."""

    from cfvs_maniskill.data import shapes as S

    keep, top, plate, hole = plate_with_opening()

    for seed in range(4):
        for add in (S.add_seal_groove, S.add_ports, S.add_fittings, S.add_offset_recess):
            body, level = add(np.random.default_rng(seed), plate, hole, top, keep)
            assert_wall_ring_at(body, hole, keep, level, seed, samples=40000, more_than=50)
            if add is S.add_fittings:
                assert body.volume > plate.volume and body.bounds[1, 2] > top + 0.009, seed
            else:
                assert body.volume < plate.volume, (add.__name__, seed)
        _, level = S.add_offset_recess(np.random.default_rng(seed), plate, hole, top, keep)
        assert top - 0.006 <= level <= top - 0.002, seed
    bars = 0
    for seed in range(12):  # a third of the bases are round bars with a flat on top
        base, at = S._block_or_bar(np.random.default_rng(seed), keep, top, (0.1, 0.3))
        n = base.face_normals
        if not np.any((np.abs(n[:, 2]) > 0.2) & (np.abs(n[:, 2]) < 0.995)):
            continue
        bars += 1
        assert_wall_ring_at(base, at, keep, top, seed, samples=40000, more_than=50)
        assert base.bounds[1, 2] == pytest.approx(top), seed  # the flat is the top
    assert bars >= 2
    assert_drawn_whole_and_held_out("manifolds", tmp_path, at_least=3)


def test_casting_features_stand_where_they_say_and_the_family_is_held_out(tmp_path):
    """`castings` (release 1.4.0's frozen set): a channel, a bevel, a raised ring and
    lightening pockets keep off the opening's wall; a hub lifts the opening 1-5 cm on a
    face of its own with sloped gussets beside it; training never draws the family."""

    from cfvs_maniskill.data import shapes as S

    keep, top, plate, hole = plate_with_opening()
    for seed in range(4):
        for add in (S.add_channel, S.add_bevel, S.add_raised_ring, S.add_lightening):
            body, level = add(np.random.default_rng(seed), plate, hole, top, keep)
            assert level == top, (add.__name__, seed)
            assert_wall_ring_at(body, hole, keep, top, seed, samples=40000, more_than=50)
            grows = add in (S.add_channel, S.add_raised_ring)
            assert (body.volume > plate.volume) == grows, (add.__name__, seed)
        hub, raised = S.add_hub(np.random.default_rng(seed), plate, hole, top, keep)
        assert 0.01 <= raised - top <= 0.05 and hub.bounds[1, 2] == pytest.approx(raised)
        assert_wall_ring_at(hub, hole, keep, raised, seed, samples=40000, more_than=20)
        n = hub.face_normals
        assert np.any((np.abs(n[:, 2]) > 0.2) & (np.abs(n[:, 2]) < 0.995)), seed  # gussets
    assert_drawn_whole_and_held_out("castings", tmp_path, at_least=4)


def test_wheel_features_stand_where_they_say_and_the_family_is_held_out(tmp_path):
    """`wheels` (release 1.5.0's frozen set): windows go through the part (the table seen
    through them), the spoked web is recessed below the face, ribs and the rim stand above
    it, teeth notch the edge, and none touches the opening's wall; training never draws
    the family."""
    import trimesh

    from cfvs_maniskill.data import shapes as S

    keep, top, hole = S.keep_clear("square", 0.004), 0.04, np.array([0.03, -0.02])
    disc = trimesh.creation.cylinder(0.12, top, 128)
    disc.apply_translation([0, 0, top / 2])

    def area_facing(mesh, z_sign: float, at: float) -> float:
        n, c = mesh.face_normals, mesh.triangles_center
        on = (n[:, 2] * z_sign > 0.999) & (np.abs(c[:, 2] - at) < 1e-6)
        return float(mesh.area_faces[on].sum())

    for seed in range(4):
        for add in S.WHEEL_FEATURES:
            body, level = add(np.random.default_rng(seed), disc, hole, top, keep)
            assert level == top, (add.__name__, seed)
            assert_wall_ring_at(body, hole, keep, top, seed, samples=40000, more_than=50)
            stands = add in (S.add_radial_ribs, S.add_outer_rim)
            assert (body.bounds[1, 2] > top + 0.004) == stands, (add.__name__, seed)
            assert (body.volume > disc.volume) == stands, (add.__name__, seed)
        windows, _ = S.add_windows(np.random.default_rng(seed), disc, hole, top, keep)
        cut_top = area_facing(disc, 1, top) - area_facing(windows, 1, top)
        cut_bottom = area_facing(disc, -1, 0.0) - area_facing(windows, -1, 0.0)
        assert cut_top > 3 * np.pi * 0.006**2 and cut_bottom == pytest.approx(cut_top, rel=0.01)
        web, _ = S.add_spoked_web(np.random.default_rng(seed), disc, hole, top, keep)
        floors = web.triangles_center[(web.face_normals[:, 2] > 0.999)][:, 2]
        assert np.any((floors < top - 0.004) & (floors > 0.3 * top)), seed  # the recess
    assert_drawn_whole_and_held_out("wheels", tmp_path, at_least=4)


def test_link_features_stand_where_they_say_and_the_family_is_held_out(tmp_path):
    """`links` (release 1.6.0's frozen set): the I-section's web and the knurl's grooves are
    recessed below the face (the knurl by at most 1.5 mm), the slot and the far bores go
    through the part, the boss lifts the opening, and none touches the opening's
    wall; training never draws the family."""
    import trimesh

    from cfvs_maniskill.data import shapes as S

    keep, top = S.keep_clear("square", 0.004), 0.03

    def area_facing(mesh, z_sign: float, at: float) -> float:
        n, c = mesh.face_normals, mesh.triangles_center
        on = (n[:, 2] * z_sign > 0.999) & (np.abs(c[:, 2] - at) < 1e-6)
        return float(mesh.area_faces[on].sum())

    for seed in range(4):
        link, hole = S._link(np.random.default_rng(seed), keep, top, (0.08, 0.12))
        assert link.is_watertight and np.hypot(*link.extents[:2]) > 0.08 + 2 * keep, seed
        for add in S.LINK_FEATURES:
            body, level = add(np.random.default_rng(seed), link, hole, top, keep)
            assert body.is_watertight and (level > top) == (add is S.add_boss), add.__name__
            assert_wall_ring_at(body, hole, keep, level, seed, samples=40000, more_than=50)
            floors = body.triangles_center[body.face_normals[:, 2] > 0.999][:, 2]
            new_floors = floors[(floors > 1e-6) & (floors < top - 1e-6)]
            if add is S.add_i_section:
                assert np.any(new_floors < top - 0.0029), seed
            if add is S.add_knurl:
                assert len(new_floors) and np.all(new_floors > top - 0.0016), seed
            if add in (S.add_radial_slot, S.add_far_bores):
                cut_top = area_facing(link, 1, top) - area_facing(body, 1, top)
                cut_bottom = area_facing(link, -1, 0.0) - area_facing(body, -1, 0.0)
                assert cut_top > 1e-5 and cut_bottom == pytest.approx(cut_top, rel=0.02), seed
        assert isinstance(link, trimesh.Trimesh)
    assert_drawn_whole_and_held_out("links", tmp_path, at_least=4)


def test_stands_raise_the_opening_or_stand_beside_it_and_are_a_training_family(tmp_path):
    """`stands` (a training family): posts keep off the opening's wall and stand 1-13 cm
    tall; most bodies put the opening on a riser above the rest of the face, so the tallest
    thing in view is often, not always, what holds it."""
    import trimesh

    from cfvs_maniskill.data import shapes as S
    from cfvs_maniskill.data.procedural import TRAINING_FAMILIES

    keep, top, plate, hole = plate_with_opening()
    for seed in range(8):
        posts, level = S.add_posts(np.random.default_rng(seed), plate, hole, top, keep)
        assert level == top and top + 0.009 < posts.bounds[1, 2] <= top + 0.13, seed
        assert_wall_ring_at(posts, hole, keep, top, seed, samples=40000, more_than=50)
    assert "stands" in TRAINING_FAMILIES
    drawn = [
        S.stand_body(np.random.default_rng(s), "square", 0.004, tmp_path, f"b{s}") for s in range(8)
    ]
    raised, bodies = 0, [(s, d) for s, d in enumerate(drawn) if d is not None]
    assert len(bodies) >= 5  # the rest: a post off the part, drawn again
    for s, (_, frame) in bodies:
        body = trimesh.load(tmp_path / f"b{s}.stl")
        z = frame["origin"][2]
        assert body.is_watertight and len(body.split(only_watertight=False)) == 1, s
        up = body.face_normals[:, 2] > 0.99  # the faces looking up: the opening's is small
        at = np.abs(body.triangles_center[:, 2] - z) < 1e-4
        raised += body.area_faces[up & at].sum() < 0.5 * body.area_faces[up].sum()
    assert 2 <= raised < len(bodies), raised
    procedural_specs(1, 5, "square", 0.004, 0.045, "stands", folder=tmp_path / "built")  # builds


def test_decoys_cut_openings_the_peg_does_not_fit_beside_it_and_are_a_training_family(
    tmp_path,
):
    """`decoys` (a training family): blind openings of other sizes keep the opening's wall
    whole and lie at least 1 cm beyond it, their floors 1-4 cm down; every body drawn is
    one watertight piece with at least one of them."""
    import trimesh

    from cfvs_maniskill.data import shapes as S
    from cfvs_maniskill.data.procedural import TRAINING_FAMILIES

    keep, top, plate, hole = plate_with_opening()
    for seed in range(6):
        body, level = S.add_other_openings(np.random.default_rng(seed), plate, hole, top, keep)
        assert level == top and body.volume < plate.volume, seed
        assert_wall_ring_at(body, hole, keep, top, seed, samples=40000, more_than=50)
        v, faces = trimesh.sample.sample_surface(body, 40000, seed=seed)
        floor = (body.face_normals[faces, 2] > 0.99) & (v[:, 2] < top - 0.009)
        assert floor.sum() > 20 and v[floor, 2].min() > top - 0.041, seed
        assert np.linalg.norm(v[floor, :2] - hole, axis=1).min() > keep + 0.01, seed
    assert "decoys" in TRAINING_FAMILIES
    drawn = [
        S.decoy_body(np.random.default_rng(s), "square", 0.004, tmp_path, f"b{s}") for s in range(8)
    ]
    assert sum(d is not None for d in drawn) >= 3  # the rest: no other opening fitted
    for s, d in enumerate(drawn):
        if d is None:
            continue
        body = trimesh.load(tmp_path / f"b{s}.stl")
        assert body.is_watertight and len(body.split(only_watertight=False)) == 1, s
        top = d[1]["origin"][2]
        floors = (body.face_normals[:, 2] > 0.99) & (body.triangles_center[:, 2] < top - 0.009)
        assert np.any(floors), s  # another opening's floor below the face


def test_a_dataset_can_be_collected_on_another_mount_than_the_profiles():
    """`--mount NAME` puts the camera on a named mount for every scene of the file (KOVIS's
    own mount given way to), and the file says so (a resume must match it)."""
    from cfvs_maniskill import resources
    from cfvs_maniskill.data.collect import CollectArgs, Collector, file_attrs
    from cfvs_maniskill.envs.task_config import load_task

    task = load_task(resources.bundled("tasks") / "PegInsert6DoF.yaml")
    for kind in ("fine", "kovis"):
        args = CollectArgs(kind=kind, mount="flange_side")
        assert Collector(args, task).env_kwargs()["camera_mount"] == "flange_side"
        assert file_attrs(args, task)["mount"] == "flange_side"
    assert "camera_mount" not in Collector(CollectArgs(kind="fine"), task).env_kwargs()
    assert "mount" not in file_attrs(CollectArgs(kind="fine"), task)


def test_a_body_no_start_pose_reaches_is_drawn_again_not_the_end_of_the_file(monkeypatch):
    """A scene the robot cannot start in (a tall post where the peg would start) makes that
    draw unusable (None: the next draw takes another body); any other error still stops."""
    from types import SimpleNamespace

    from cfvs_maniskill import resources
    from cfvs_maniskill.data.collect import CollectArgs, Collector
    from cfvs_maniskill.envs.task_config import load_task

    task = load_task(resources.bundled("tasks") / "PegInsert6DoF.yaml")
    collector = Collector(CollectArgs(kind="coarse"), task)
    failure = RuntimeError("no reachable scene in 100 tries for procs_1_0001")

    def reset(seed, options):
        raise failure

    env = SimpleNamespace(unwrapped=SimpleNamespace(defer_obs=False), reset=reset)
    monkeypatch.setattr(collector, "_env_for", lambda group: env)
    assert collector.sample(0) is None
    assert env.unwrapped.defer_obs is False
    failure = RuntimeError("the renderer died")
    with pytest.raises(RuntimeError, match="renderer died"):
        collector.sample(0)
