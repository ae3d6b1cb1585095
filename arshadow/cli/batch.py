"""``arshadow batch``: photos and videos under one scene file, resumable, locally or on a Dask cluster."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Any

from . import EXIT_OK, EXIT_SOME_FAILED
from .light import add_probe_options

if TYPE_CHECKING:
    from distributed import Client, LocalCluster

    from ..frame.session import Session
    from ..scene.spec import SceneSpec

EPILOG = """\
examples:
  arshadow batch shots/*.jpg clips/*.mp4 --config job.yml -o out/
  arshadow batch clips/*.mp4 --config job.yml -o /shared/out --dask tcp://scheduler:8786
  arshadow batch clips/*.mp4 --config job.yml -o out --dask local:2

job.yml is a scene file (docs/architecture.md: the `arshadow render` option names, e.g. calib,
marker_length, model, place, lights). Run the same command again after an interruption (even kill -9):
finished items are skipped (OUT_DIR/.arshadow-batch/<stem>.json records them), unfinished ones are redone;
outputs are never half-written. OUT_DIR/batch.json lists every item's status.
exit status: 0 every item done, 1 some item failed or is damaged / without marker (the others were
processed), 2 bad usage or an unreadable scene file.
"""


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from .map import add_map_option
    from .video import add_output_options

    p = subparsers.add_parser(
        "batch",
        help="process photos and videos under one scene file (resumable; Dask optional)",
        description="Composite the scene of a job file into every photo and video given, skipping the items "
        "an earlier run finished.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("inputs", nargs="+", metavar="INPUT", help="photos and videos (videos by extension)")
    p.add_argument("--config", "-c", required=True, metavar="JOB.yml", help="scene file (YAML or JSON)")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder (created if missing)")
    v = p.add_argument_group("video")
    v.add_argument("--smooth", type=int, default=10, metavar="K", help="pose smoothing half-window (frames)")
    v.add_argument("--hold", type=int, default=12, metavar="N", help="frames a lost marker's pose is held")
    v.add_argument("--pose-lag", type=int, default=16, metavar="K", help="IPPE branch look-ahead (frames)")
    v.add_argument("--max-frames", type=int, metavar="N", help="only the first N frames of each video")
    add_output_options(p.add_argument_group("output"))
    add_probe_options(p, run=True)
    add_map_option(p)  # --map auto|FILE (cli/map.py)
    p.add_argument(
        "--dask",
        metavar="ADDRESS",
        help="run on a Dask cluster: a scheduler address (tcp://host:8786) or local[:N] for a "
        "LocalCluster of N worker processes (needs arshadow[dask])",
    )
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar")
    p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="show tracebacks")
    p.set_defaults(func=run)


def _with_map(args: argparse.Namespace, spec: SceneSpec) -> SceneSpec:
    """``--map auto|FILE``: the scene with the map file as its board (cli/map.py)."""
    from dataclasses import replace

    from .map import resolve_map

    t = spec.tracker
    board = resolve_map(
        args,
        args.inputs,
        args.output,
        calib=spec.camera,
        marker_length=t.marker_length,
        dictionary=t.dictionary,
        marker_id=t.marker_id,
        inverted=t.inverted,
        board=t.board,
    )
    return spec if board is None else replace(spec, tracker=replace(t, board=board, marker_length=None))


#: seconds to wait for a Dask scheduler before giving up (a wrong address must not hang the run)
DASK_CONNECT_TIMEOUT_S = 10


def _client(address: str, debug: bool = False) -> tuple[Client, LocalCluster | None]:
    """``(Client, LocalCluster or None)`` for ``--dask ADDRESS``; UsageError for a bad or unreachable one."""
    import logging

    from ..errors import UsageError

    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise UsageError("--dask needs Dask: pip install 'arshadow[dask]'") from None
    if not debug:  # the scheduler's and workers' INFO chatter
        logging.getLogger("distributed").setLevel(logging.WARNING)
    head, sep, n = address.partition(":")
    if head == "local":  # (not localhost:8786, a scheduler address)
        try:
            workers = int(n) if sep else 2
        except ValueError:
            workers = 0
        if not workers >= 1:
            raise UsageError(f"--dask {address}: use local or local:N with N >= 1 worker processes")
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
        return Client(cluster), cluster
    if "://" not in address and ":" not in address:
        raise UsageError(f"--dask {address}: give a scheduler address (tcp://HOST:PORT) or local[:N]")
    if not debug:  # a lost scheduler is arshadow's one line, not the client's reconnection tracebacks
        names = [n for n in logging.root.manager.loggerDict if n.startswith("distributed.")]
        for name in ["distributed", "distributed.client", "distributed.utils", *names]:
            logging.getLogger(name).setLevel(logging.CRITICAL)
    try:
        return Client(address, timeout=DASK_CONNECT_TIMEOUT_S), None
    except (OSError, TimeoutError, ValueError) as exc:
        why = str(exc).strip().splitlines()[0][:160] if str(exc).strip() else type(exc).__name__
        raise UsageError(
            f"--dask {address}: cannot reach the scheduler within {DASK_CONNECT_TIMEOUT_S} s ({why})"
        ) from None


def run(args: argparse.Namespace) -> int:
    from ..frame.session import Session
    from ..io import check_output_folder
    from ..scene.spec import load_scene
    from ..video.batch import run_batch
    from . import quiet_opencv
    from .light import probe_estimate
    from .video import engine_options

    debug = bool(getattr(args, "debug", False))
    quiet_opencv(debug)
    spec = load_scene(args.config)
    est = probe_estimate(
        args,
        args.inputs,
        calib=spec.camera,
        marker_length=spec.tracker.marker_length,
        dictionary=spec.tracker.dictionary,
        marker_id=spec.tracker.marker_id,
    )
    if est is not None:  # --probe: the measured light replaces the file's (docs/light.md)
        spec = load_scene(args.config, light_from=est, lights=[est.light])
    spec = _with_map(args, spec)  # --map: the markers' map learned (or read) first
    opts = engine_options(args)
    # before any work: a bad -o, scene file or cluster address is one usage error (exit 2)
    outdir = check_output_folder(args.output, "-o")
    client: Client | None = None
    cluster: LocalCluster | None = None
    session: Session | None = None
    if args.dask:
        spec.build()  # the scene's files, read here once: a bad one fails before any task is sent
        client, cluster = _client(args.dask, debug)
    else:
        session = Session(spec)
    bar = None
    if not args.quiet and sys.stderr.isatty():  # no bar in a log file: the closing summary line only
        from tqdm import tqdm

        bar = tqdm(total=len(args.inputs), unit="item", desc="batch", file=sys.stderr, dynamic_ncols=True)

    def progress(done: int, total: int, res: dict[str, Any] | None) -> None:
        if bar is not None:
            bar.update(done - bar.n)
        if res is not None and res["status"] != "ok":
            msg = res.get("error") or "; ".join(res.get("warnings") or []) or res["status"]
            (bar.write if bar is not None else print)(f"arshadow batch: {res['status']}: {msg}", file=sys.stderr)
        elif res is not None and res.get("warnings"):  # done, with something to say (a flagged pose)
            for w in res["warnings"]:
                (bar.write if bar is not None else print)(f"arshadow batch: warning: {w}", file=sys.stderr)

    try:
        summary = run_batch(
            spec,
            args.inputs,
            outdir,
            opts,
            save_mask=bool(args.save_mask),
            client=client,
            progress=progress,
            session=session,
            jobs=args.jobs,
        )
    finally:
        if bar is not None:
            bar.close()
        if session is not None:
            session.close()
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    c = summary["counts"]
    print(
        f"{len(summary['items'])} items: "
        + ", ".join(f"{k} {v}" for k, v in sorted(c.items()))
        + f"  (summary: {outdir / 'batch.json'})"
    )
    failed = sum(1 for r in summary["items"] if r["status"] != "ok")
    return EXIT_SOME_FAILED if failed else EXIT_OK
