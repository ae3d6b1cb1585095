"""A real Dask cluster on 127.0.0.1 for tests and benchmarks: ``dask scheduler`` and ``dask worker
--nworkers N`` started as separate processes (tcp, not a LocalCluster), and a small batch of clips.

Used by tests/test_dask_cluster.py and tests/benchmarks/bench_dask_faults.py. Every process started here
is in its own process group and is killed (by its id) when the context ends; start-up is bounded.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from video_clips import BOX_JOB

ROOT = Path(__file__).resolve().parents[1]
CALIB = ROOT / "calib" / "synth_640x360.yml"
#: the batch's scene: the video tests' box (video_clips.BOX_JOB), edge-refined corners, the numpy compose path
JOB = {**BOX_JOB, "refine": "edge", "compose": "cpu"}
#: frame-record keys that must be equal between a cluster run and the one-process run
KEYS = ("frame", "time_s", "status", "marker_ids", "rvec", "tvec", "raw", "reprojection_error_px", "pose_choice")


def _dask_cmd() -> list:
    return [sys.executable, "-m", "dask"]


class Cluster:
    """A scheduler and ``nworkers`` worker processes (one thread each) on 127.0.0.1."""

    def __init__(self, workdir, nworkers: int = 2, preload=None, start_timeout: float = 90.0):
        self.workdir = Path(workdir)
        self.workdir.mkdir(parents=True, exist_ok=True)
        self.file = self.workdir / "scheduler.json"
        self.nworkers = nworkers
        self.preload = preload
        self.start_timeout = start_timeout
        self.scheduler = None
        self.workers = None
        self.address = None

    def _popen(self, args, log):
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), str(ROOT / "tests")]))
        env.setdefault("OMP_NUM_THREADS", "1")
        return subprocess.Popen(
            [*_dask_cmd(), *args],
            stdout=open(self.workdir / log, "ab"),  # noqa: SIM115 (closed with the process)
            stderr=subprocess.STDOUT,
            env=env,
            start_new_session=True,  # its own process group: killed as one, never by name
        )

    def start_scheduler(self) -> None:
        with contextlib.suppress(FileNotFoundError):
            self.file.unlink()
        self.scheduler = self._popen(
            [
                "scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                str(getattr(self, "port", 0) or 0),
                "--no-dashboard",
                "--idle-timeout",  # a scheduler left behind (its test killed) ends by itself; its workers
                "600s",  # follow (--death-timeout)
                "--scheduler-file",
                str(self.file),
            ],
            "scheduler.log",
        )
        t0 = time.time()
        while not self.file.exists():
            if time.time() - t0 > self.start_timeout or self.scheduler.poll() is not None:
                raise RuntimeError(f"dask scheduler did not start: {self.log('scheduler.log')}")
            time.sleep(0.05)
        time.sleep(0.05)
        self.address = json.loads(self.file.read_text())["address"]
        self.port = int(self.address.rsplit(":", 1)[1])  # a restarted scheduler takes the same port

    def start_workers(self) -> None:
        args = ["worker", self.address, "--nworkers", str(self.nworkers), "--nthreads", "1", "--no-dashboard"]
        args += ["--death-timeout", "60", "--local-directory", str(self.workdir / "workers")]
        if self.preload is not None:
            args += ["--preload", str(self.preload)]
        self.workers = self._popen(args, "workers.log")

    def wait_workers(self, client, n=None) -> None:
        n = self.nworkers if n is None else n
        try:
            client.wait_for_workers(n, timeout=self.start_timeout)
        except TimeoutError:
            raise RuntimeError(f"{n} dask workers did not start: {self.log('workers.log')}") from None

    def log(self, name) -> str:
        p = self.workdir / name
        return p.read_text(errors="replace")[-2000:] if p.exists() else ""

    def kill_scheduler(self) -> None:
        _kill_group(self.scheduler)
        self.scheduler = None

    def close(self) -> None:
        _kill_group(self.workers)
        _kill_group(self.scheduler)
        self.workers = self.scheduler = None

    def __enter__(self) -> Cluster:
        try:
            self.start_scheduler()
            self.start_workers()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _kill_group(proc) -> None:
    """SIGKILL the process group started by this module (its id is the process's own)."""
    if proc is None:
        return
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(proc.pid, signal.SIGKILL)
    with contextlib.suppress(subprocess.TimeoutExpired):
        proc.wait(10)


def make_clips(folder, n_videos: int = 3, n: int = 36, gop: int = 12) -> list:
    """``n_videos`` H.264 clips of ``n`` frames (a keyframe every ``gop``: ``n // gop`` chunks), each on
    its own camera path."""
    from video_clips import make_clip

    from arshadow.camera.model import Intrinsics
    from arshadow.synth.markers import camera_path

    intr = Intrinsics.from_file(CALIB)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for v in range(n_videos):
        poses = camera_path(n, radius=0.5, height=(0.3, 0.42), sweep_deg=30.0, start_deg=-120.0 + 25.0 * v)
        out.append(make_clip(folder / f"v{v}.mp4", intr, poses, noise=1.0, seed=v, gop=gop))
    return out


def frame_records(path) -> list:
    """The compared keys of every line of a ``*.frames.jsonl``."""
    return [{k: d.get(k) for k in KEYS} for d in map(json.loads, Path(path).read_text().splitlines())]


def outputs_equal(a_dir, b_dir, stems) -> list:
    """The differences between two batch outputs (frame records exact, mask frames exact): [] if none."""
    import av
    import numpy as np

    diffs = []
    for s in stems:
        for name in (f"{s}.frames.jsonl", f"{s}.shadow.mkv", f"{s}.mp4"):
            if not (Path(b_dir) / name).exists():
                diffs.append(f"{name}: missing")
        if diffs:
            continue
        if frame_records(Path(a_dir) / f"{s}.frames.jsonl") != frame_records(Path(b_dir) / f"{s}.frames.jsonl"):
            diffs.append(f"{s}.frames.jsonl differs")
        masks = []
        for d in (a_dir, b_dir):
            with av.open(str(Path(d) / f"{s}.shadow.mkv")) as c:
                masks.append([f.to_ndarray(format="gray") for f in c.decode(video=0)])
        if len(masks[0]) != len(masks[1]) or not all(np.array_equal(x, y) for x, y in zip(*masks, strict=True)):
            diffs.append(f"{s}.shadow.mkv differs")
    return diffs
