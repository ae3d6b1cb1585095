"""Batches on a real Dask cluster, repeated, clean and with a worker killed (the cluster and flags work items 1-2).

    python tests/benchmarks/bench_dask_faults.py [--runs 100] [--kill-runs 20] [--max-minutes 0]
                                                 [--videos 3] [--frames 36] [--seed 31] [--out r.json]

One ``dask scheduler`` and ``dask worker --nworkers 2 --nthreads 1`` started as separate processes on
127.0.0.1 (tests/dask_cluster.py); three synthetic clips of 36 frames with a keyframe every 12 (three
chunks each, ``--jobs 3``); the ground truth is the one-process run of the same batch (``run_batch``
without a client). Then:

- ``--runs`` clean runs, each into a fresh output folder: a failure is any item not ``ok``, an exception,
  or outputs (per-frame records, lossless mask frames) differing from the one-process run;
- ``--kill-runs`` runs in which one worker process is SIGKILLed at a random moment (uniform in 0.2 s ..
  the median clean run's wall time; its nanny starts another): same failure test.

``--max-minutes``: stop starting runs after this long (0: no limit); the JSON says how many ran. Prints
JSON: counts of runs and failures per kind, the failures' messages, wall time per run (median, min, max),
the machine's load. Judged: 100 clean runs with 0 failures, 20 killed runs with outputs identical.
"""

from __future__ import annotations

import argparse
import os
import random
import shutil
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

import _common  # noqa: E402
from dask_cluster import JOB, Cluster, make_clips, outputs_equal  # noqa: E402


def _one(client, clips, out, spec, opts, stems, local):
    from arshadow.video.batch import run_batch

    t = time.perf_counter()
    try:
        s = run_batch(spec, clips, out, opts, save_mask=True, client=client, jobs=3)
    except Exception as exc:  # noqa: BLE001 (a failure of the run: counted)
        return time.perf_counter() - t, [f"{type(exc).__name__}: {exc}"]
    wall = time.perf_counter() - t
    bad = [f"{it['stem']}: {it['status']}: {it.get('error')}" for it in s["items"] if it["status"] != "ok"]
    return wall, bad or outputs_equal(local, out, stems)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--kill-runs", type=int, default=20)
    ap.add_argument("--max-minutes", type=float, default=0.0)
    ap.add_argument("--videos", type=int, default=3)
    ap.add_argument("--frames", type=int, default=36)
    ap.add_argument("--seed", type=int, default=31)
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    import distributed

    from arshadow.scene.spec import scene_from_dict
    from arshadow.video.batch import run_batch
    from arshadow.video.engine import EngineOptions

    rng = random.Random(a.seed)
    t_end = time.time() + a.max_minutes * 60 if a.max_minutes > 0 else float("inf")
    work = Path(tempfile.mkdtemp(prefix="arshadow-dask-faults."))
    spec, opts = scene_from_dict(JOB), EngineOptions(mask="mkv", contact_sheet=0)
    clips = make_clips(work / "clips", n_videos=a.videos, n=a.frames, gop=a.frames // 3)
    stems = [f"v{i}" for i in range(a.videos)]
    local = work / "local"
    run_batch(spec, clips, local, opts, save_mask=True)
    res = {"clean": {"runs": 0, "failures": [], "wall_s": []}, "killed": {"runs": 0, "failures": [], "wall_s": []}}
    try:
        with Cluster(work / "cluster") as cl, distributed.Client(cl.address, timeout=30) as client:
            cl.wait_workers(client)
            for i in range(a.runs):
                if time.time() > t_end:
                    break
                out = work / f"clean{i}"
                wall, bad = _one(client, clips, out, spec, opts, stems, local)
                r = res["clean"]
                r["runs"] += 1
                r["wall_s"].append(round(wall, 2))
                r["failures"] += [f"run {i}: {b}" for b in bad]
                shutil.rmtree(out, ignore_errors=True)
                print(f"clean {i}: {wall:.1f} s {'OK' if not bad else bad}", file=sys.stderr, flush=True)
            typical = sorted(res["clean"]["wall_s"])[len(res["clean"]["wall_s"]) // 2] if res["clean"]["wall_s"] else 10
            for i in range(a.kill_runs):
                if time.time() > t_end:
                    break
                cl.wait_workers(client)
                pids = sorted(client.run(os.getpid).values())
                victim, delay = rng.choice(pids), rng.uniform(0.2, typical)
                timer = threading.Timer(delay, lambda p=victim: os.kill(p, signal.SIGKILL))
                timer.start()
                out = work / f"killed{i}"
                wall, bad = _one(client, clips, out, spec, opts, stems, local)
                timer.join()
                r = res["killed"]
                r["runs"] += 1
                r["wall_s"].append(round(wall, 2))
                r["failures"] += [f"run {i} (killed at {delay:.2f} s): {b}" for b in bad]
                shutil.rmtree(out, ignore_errors=True)
                msg = "OK" if not bad else bad
                print(f"killed {i} at {delay:.1f} s: {wall:.1f} s {msg}", file=sys.stderr, flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    for r in res.values():
        r["failed_runs"] = len({f.split(":")[0] for f in r["failures"]})
        r["wall_s_summary"] = _common.summary(r["wall_s"]) if r["wall_s"] else None
    res["meta"] = _common.metadata()
    res["setup"] = {"videos": a.videos, "frames": a.frames, "chunks": 3, "workers": 2, "seed": a.seed}
    _common.emit(res, a.out)
    return 0 if not (res["clean"]["failures"] or res["killed"]["failures"]) else 1


if __name__ == "__main__":
    raise SystemExit(main())
