"""Batches on a real Dask cluster under races and faults (the cluster and flags work items 1-2).

The cluster is ``dask scheduler`` + ``dask worker --nworkers 2`` started as separate processes on
127.0.0.1 (tests/dask_cluster.py), not a LocalCluster. Ground truth is the one-process run of the same
batch (``run_batch`` without a client): the per-frame records and the lossless mask frames must be equal
(the one-process run is itself checked against the generating poses elsewhere).

- the chunk-store race: two videos whose joins remove the shared ``OUT/.arshadow-chunks`` at the same
  moment (the window widened on the workers by tests/dask_widen.py: every run of the old code lost a video
  with ``FileNotFoundError: .../.arshadow-chunks``);
- a worker killed (SIGKILL) at a random moment: the batch completes, outputs equal (slow);
- the scheduler killed: the client fails with one line, the rerun on a new cluster resumes from the
  finished chunks (slow);
- the output disk full (a small tmpfs; root only): one line, no half-written file, the rerun completes
  once space is freed.

The repeated runs (100 clean, 20 with a worker killed) are tests/benchmarks/bench_dask_faults.py.
"""

from __future__ import annotations

import json
import os
import random
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from dask_cluster import JOB, ROOT, Cluster, make_clips, outputs_equal

distributed = pytest.importorskip("distributed")
pytestmark = pytest.mark.gl


@pytest.fixture(scope="module")
def batch3(tmp_path_factory):
    """Three clips (v0, v1, v2: 36 frames, a keyframe every 12) and their one-process run."""
    d = tmp_path_factory.mktemp("batch3")
    clips = make_clips(d / "clips")
    _reference(clips, d / "local")
    return clips, d / "local"


def _spec_opts():
    from arshadow.scene.spec import scene_from_dict
    from arshadow.video.engine import EngineOptions

    return scene_from_dict(JOB), EngineOptions(mask="mkv", contact_sheet=0)


def _reference(clips, out):
    from arshadow.video.batch import run_batch

    spec, opts = _spec_opts()
    s = run_batch(spec, clips, out, opts, save_mask=True)
    assert s["counts"]["ok"] == len(clips)
    return s


def _on_cluster(client, clips, out):
    from arshadow.video.batch import run_batch

    spec, opts = _spec_opts()
    return run_batch(spec, clips, out, opts, save_mask=True, client=client, jobs=3)


def test_two_videos_joining_at_once_on_a_real_scheduler(tmp_path, batch3):
    """Two videos x three chunks on a scheduler + 2 worker processes, their joins made to remove the
    shared chunk folder together: both videos are written, equal to the one-process run."""
    clips, local = batch3[0][:2], batch3[1]
    with (
        Cluster(tmp_path / "cluster", preload=ROOT / "tests" / "dask_widen.py") as cl,
        distributed.Client(cl.address, timeout=30) as client,
    ):
        cl.wait_workers(client)
        s = _on_cluster(client, clips, tmp_path / "dask")
    assert [it["status"] for it in s["items"]] == ["ok", "ok"], [it.get("error") for it in s["items"]]
    assert [it["chunks"] for it in s["items"]] == [3, 3]
    assert outputs_equal(local, tmp_path / "dask", ["v0", "v1"]) == []
    assert not (tmp_path / "dask" / ".arshadow-chunks").exists()


@pytest.mark.slow
def test_a_worker_killed_at_a_random_moment_changes_no_output(tmp_path, batch3):
    """Three videos x three chunks; one worker process SIGKILLed 0.5-6 s in (its nanny starts another):
    every video is written, equal to the one-process run."""
    clips, local = batch3
    rng = random.Random(int(os.environ.get("ARSHADOW_TEST_SEED", "31")))
    with Cluster(tmp_path / "cluster") as cl, distributed.Client(cl.address, timeout=30) as client:
        cl.wait_workers(client)
        pids = sorted(client.run(os.getpid).values())
        killed = []

        def kill():
            time.sleep(rng.uniform(0.5, 6.0))
            os.kill(pids[0], signal.SIGKILL)  # a worker process this test's cluster started
            killed.append(pids[0])

        t = threading.Thread(target=kill)
        t.start()
        s = _on_cluster(client, clips, tmp_path / "dask")
        t.join()
    assert killed
    assert [it["status"] for it in s["items"]] == ["ok"] * 3, [it.get("error") for it in s["items"]]
    assert outputs_equal(local, tmp_path / "dask", ["v0", "v1", "v2"]) == []


def _batch_cmd(clips, out, address, job):
    return [
        sys.executable,
        "-m",
        "arshadow",
        "batch",
        *map(str, clips),
        "--config",
        str(job),
        "-o",
        str(out),
        "--save-mask",
        "--contact-sheet",
        "0",
        "--jobs",
        "3",
        "--dask",
        address,
        "-q",
    ]


def _job_file(tmp_path):
    import yaml

    p = tmp_path / "job.yml"
    p.write_text(yaml.safe_dump(JOB))
    return p


@pytest.mark.slow
def test_scheduler_killed_fails_in_one_line_and_the_rerun_resumes(tmp_path, batch3):
    """The scheduler SIGKILLed once a chunk is recorded: ``arshadow batch`` exits 1 with one line saying
    so; the same command on a new cluster resumes from the finished chunks and writes outputs equal to the
    one-process run."""
    clips, local = batch3
    out, job = tmp_path / "dask", _job_file(tmp_path)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    store = out / ".arshadow-chunks"
    with Cluster(tmp_path / "c1") as cl:
        with distributed.Client(cl.address, timeout=30) as client:
            cl.wait_workers(client)
        proc = subprocess.Popen(
            _batch_cmd(clips, out, cl.address, job), env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        t0 = time.time()
        while time.time() - t0 < 120 and proc.poll() is None:
            if list(store.glob("*/c*.json")):
                break
            time.sleep(0.01)
        assert proc.poll() is None, "the batch ended before the scheduler could be killed"
        cl.kill_scheduler()
        _, err = proc.communicate(timeout=120)
    lines = [
        ln for ln in err.splitlines() if ln.strip() and ": warning: " not in ln
    ]  # flagged poses: the cluster and flags work.3
    assert proc.returncode == 1, err
    assert len(lines) == 1, err
    assert "scheduler" in lines[0] and "was lost" in lines[0] and "rerun the same command" in lines[0]
    kept = list(store.glob("*/c*.json"))
    assert kept
    with Cluster(tmp_path / "c2") as cl:
        with distributed.Client(cl.address, timeout=30) as client:
            cl.wait_workers(client)
        rc = subprocess.run(_batch_cmd(clips, out, cl.address, job), env=env, capture_output=True, text=True)
    assert rc.returncode == 0, rc.stderr
    items = json.loads((out / "batch.json").read_text())["items"]
    assert sum(it.get("chunks_resumed", 0) for it in items if not it.get("skipped")) >= 1 or any(
        it.get("skipped") for it in items
    )
    assert outputs_equal(local, out, ["v0", "v1", "v2"]) == []


def _mount_tmpfs(path: Path, size: str) -> bool:
    path.mkdir(parents=True, exist_ok=True)
    if os.geteuid() != 0 or shutil.which("mount") is None:
        return False
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)], capture_output=True)
    return r.returncode == 0


def test_output_disk_full_is_one_line_nothing_half_written_and_the_rerun_completes(tmp_path, batch3):
    """``-o`` on a 3 MiB tmpfs nearly filled: ``arshadow batch`` exits 1 with one line naming the full
    disk; no temporary and no partial output is left (every output there is whole: equal to the
    one-process run's); with the space freed, the same command completes."""
    clips, local = batch3
    need = sum(p.stat().st_size for p in local.iterdir() if p.is_file())
    disk = tmp_path / "disk"
    if not _mount_tmpfs(disk, "3m"):
        pytest.skip("needs root to mount a tmpfs")
    try:
        filler = disk / "filler"
        free = shutil.disk_usage(disk).free
        filler.write_bytes(b"\0" * max(0, free - need // 2))  # about half the batch's outputs fit
        out, job = disk / "out", _job_file(tmp_path)
        cmd = _batch_cmd(clips, out, "x", job)
        cmd = cmd[: cmd.index("--dask")] + ["-q"]
        cmd.remove("--jobs")
        cmd.remove("3")
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
        lines = [ln for ln in r.stderr.splitlines() if ln.strip() and ": warning: " not in ln]
        assert r.returncode == 1 and len(lines) == 1, r.stderr
        assert "no space left on the output disk" in lines[0] and "rerun the same command" in lines[0]
        left = [p for p in out.rglob("*") if ".tmp" in p.name]
        assert left == []
        done = [s for s in ("v0", "v1", "v2") if (out / f"{s}.frames.jsonl").exists()]
        assert outputs_equal(local, out, done) == []
        assert len(done) < 3
        filler.unlink()
        r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr
        assert outputs_equal(local, out, ["v0", "v1", "v2"]) == []
    finally:
        subprocess.run(["umount", "-l", str(disk)], capture_output=True)
