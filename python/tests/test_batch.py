"""`clothsr.batch`: many shots on a local pool and on a real Ray cluster of two nodes on
127.0.0.1, started by the test; one task's worker process is killed mid-run (.ci/run: the
`python` stage installs ray in the usd-core 26.11 venv)."""

import json
import os
import pathlib
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from pxr import Usd, UsdGeom

from clothsr import batch

ROOT = pathlib.Path(__file__).resolve().parents[2]
FRAMES = 40


def shots(tmp_path):
    """Four small shots: the three sample sheets and the sphere's again under another name."""
    src = tmp_path / "shots"
    src.mkdir()
    out = []
    for name, sample in [
        ("sphere", "sheet_sphere"),
        ("balls", "sheet_three_balls"),
        ("table", "sheet_table"),
        ("sphere_again", "sheet_sphere"),
    ]:
        p = src / f"{name}.usda"
        shutil.copy(ROOT / "samples" / f"{sample}.usda", p)
        out.append(p)
    return out


def fine_points(path):
    """{time code: points} of every garment mesh of a standalone output."""
    stage = Usd.Stage.Open(str(path))
    out = {}
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.Mesh) and "/Garments/" in str(prim.GetPath()):
            attr = UsdGeom.Mesh(prim).GetPointsAttr()
            for t in attr.GetTimeSamples():
                out[(str(prim.GetPath()), t)] = np.array(attr.Get(t))
    return out


def same(a, b):
    return a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)


def shot_tasks():
    """PIDs of the processes running a shot task (Ray titles them ``ray::shot_task``)."""
    pids = []
    for d in pathlib.Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                cmd = (d / "cmdline").read_bytes().split(b"\0")[0]
            except OSError:
                continue
            if cmd.startswith(b"ray::shot_task"):
                pids.append(int(d.name))
    return pids


def test_a_bad_shot_is_reported_not_retried_and_the_others_run(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    bad = tmp_path / "bad.usda"
    bad.write_text("#usda 1.0\ndef Mesh \"m\" {\n  point3f[] points = [(0, 0, 0)\n")
    good = tmp_path / "good.usda"
    shutil.copy(ROOT / "samples" / "sheet_sphere.usda", good)
    s = batch.run_batch([bad, good], out, frames=2, layer=False, workers=2, quiet=True)
    assert [x["status"] for x in s["shots"]] == ["failed", "ok"]
    assert s["shots"][0]["error"]["kind"] == "input"
    assert "bad.usda" in s["shots"][0]["error"]["message"]
    assert s["exit_code"] == 3 and s["status"] == "failed"
    assert s["shots"][1]["frames_computed"] == 2
    assert (out / "good.usdc").exists() and not (out / "bad.usdc").exists()
    # Two shots writing one output are refused before any runs.
    s = batch.run_batch([good, good], out, frames=2, quiet=True)
    assert s["exit_code"] == 2 and not s["shots"], s


def test_a_child_that_prints_does_not_garble_its_result(tmp_path, monkeypatch):
    # Every child process prints to stdout as it starts (a host's site hook, a chatty library).
    noise = tmp_path / "noise"
    noise.mkdir()
    (noise / "sitecustomize.py").write_text('print("{not json", flush=True)\n')
    monkeypatch.setenv("PYTHONPATH", str(noise))
    good = tmp_path / "good.usda"
    shutil.copy(ROOT / "samples" / "sheet_sphere.usda", good)
    (tmp_path / "out").mkdir()
    s = batch.run_batch([good], tmp_path / "out", frames=1, layer=False, workers=1, quiet=True)
    assert [x["status"] for x in s["shots"]] == ["ok"], s
    assert s["shots"][0]["frames_computed"] == 1


@pytest.fixture(scope="module")
def cluster():
    """A head and one more node, one CPU each, on 127.0.0.1 only."""
    pytest.importorskip("ray")
    from ray.cluster_utils import Cluster

    node = {"num_cpus": 1, "node_ip_address": "127.0.0.1"}
    c = Cluster(initialize_head=True, head_node_args=dict(node, include_dashboard=False))
    try:
        c.add_node(**node)
        assert c.address.startswith("127.0.0.1:"), c.address
        yield c.address
    finally:
        c.shutdown()


def test_a_ray_cluster_runs_the_batch_and_resumes_a_killed_task(tmp_path, cluster):
    inputs = shots(tmp_path)
    local, on_ray = tmp_path / "local", tmp_path / "ray"
    local.mkdir()
    on_ray.mkdir()
    common = ["--frames", str(FRAMES), "--layer", "off", "--publish-every-s", "0", "--json"]
    # The same batch on the local pool: the reference.
    run = subprocess.run(
        [sys.executable, "-m", "clothsr.batch", *map(str, inputs), "--out-dir", str(local)]
        + common
        + ["--workers", "2"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert run.returncode == 0 and run.stdout.strip(), run.stderr[-3000:]
    reference = json.loads(run.stdout.strip().splitlines()[-1])
    assert [s["frames_computed"] for s in reference["shots"]] == [FRAMES] * 4

    driver = subprocess.Popen(
        [sys.executable, "-m", "clothsr.batch", *map(str, inputs), "--out-dir", str(on_ray)]
        + common
        + ["--ray", cluster],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    # Both nodes' first shots have published a resume point (a hidden file beside the
    # output), seconds into shots that take tens of seconds: kill one of them.
    deadline = time.monotonic() + 180
    killed = None
    while killed is None and time.monotonic() < deadline and driver.poll() is None:
        running = shot_tasks()
        if len(list(on_ray.glob(".*.clothsr-resume.safetensors"))) >= 2 and running:
            os.kill(running[0], signal.SIGKILL)
            killed = running[0]
        time.sleep(0.2)
    stdout, stderr = driver.communicate(timeout=240)
    assert killed is not None, "no shot task was found running: " + stderr[-2000:]
    assert stdout.strip(), f"no summary (exit {driver.returncode}): " + stderr[-3000:]
    summary = json.loads(stdout.strip().splitlines()[-1])
    assert driver.returncode == 0 and summary["exit_code"] == 0, stderr[-2000:]
    assert [s["status"] for s in summary["shots"]] == ["ok"] * 4
    # The killed task ran again and went on from its shot's last published frame.
    resumed = [s for s in summary["shots"] if s["resumed_after"]]
    assert len(resumed) == 1, summary
    assert 0 < resumed[0]["resumed_after"] < FRAMES
    assert resumed[0]["frames_computed"] == FRAMES - resumed[0]["resumed_after"]
    for shot in inputs:
        name = shot.stem + ".usdc"
        a, b = fine_points(local / name), fine_points(on_ray / name)
        assert len(a) == FRAMES + 1
        assert same(a, b), f"{name}: the Ray batch's output differs from the local one's"


def folder_files(root):
    """{path relative to root: bytes} of a models folder, apart from the training log (wall
    times) and the weights file (random parameter ids; the held-out figures in
    held_out.csv and report.md are the network's outputs)."""
    out = {}
    for p in sorted(root.rglob("*")):
        if p.is_file() and p.name not in ("log.csv", "model.bpk"):
            text = p.read_bytes().replace(os.fsencode(root), b"MODELS")
            out[str(p.relative_to(root))] = text
    return out


def test_a_fit_on_ray_makes_the_models_a_local_fit_makes(tmp_path, cluster):
    """The fit's tasks fan out over both nodes; on one thread each, its models are the local
    fit's bit for bit."""
    tiny = dict(coarse_mm=40, fine_mm=10, frames=3, isr_steps=60, from_scratch=True)
    local, on_ray = tmp_path / "local", tmp_path / "ray"
    sample = ROOT / "samples" / "sheet_sphere.usda"
    code = (
        "import sys, json; from clothsr import batch; "
        "batch.fit(sys.argv[1], sys.argv[2], ray=sys.argv[3] or None, quiet=True, "
        "**json.loads(sys.argv[4]))"
    )
    for folder, address in [(local, ""), (on_ray, cluster)]:
        r = subprocess.run(
            [sys.executable, "-c", code, str(sample), str(folder), address, json.dumps(tiny)],
            env=dict(os.environ, RAYON_NUM_THREADS="1"),
            capture_output=True,
            text=True,
            check=False,
        )
        assert r.returncode == 0, r.stderr[-3000:]
    a, b = folder_files(local), folder_files(on_ray)
    assert a.keys() == b.keys()
    assert "held_out.csv" in a and "coarse.json" in a
    for name in a:
        assert a[name] == b[name], f"{name} differs"
