"""The shared chunk-store folder ``OUT/.arshadow-chunks`` under concurrent videos (the cluster and flags work).

Every video of a batch keeps its finished chunks in ``OUT/.arshadow-chunks/<stem>-<fp>/``; the video's
join removes its own folder and then the shared parent when it is empty. On a cluster, videos open and
remove their stores at the same moments, so:

- a store opened while another video's join removes the (momentarily empty) parent must still be made
  (the parent removed between the creation of the parent and of the sub-folder);
- two joins removing the parent at once must both succeed (the loser finds it gone);
- a join removing the parent while another video's store is being created must leave that store whole
  (the parent is no longer empty: not removed, no error).

The windows are made deterministic by hooking ``os.mkdir`` / ``os.rmdir`` (what ``pathlib`` and
``os.makedirs`` call) to run the other video's step right inside them; a hammer of threads and of
processes then runs many opens and removes at once. The real-scheduler runs are in
tests/test_dask_cluster.py.
"""

from __future__ import annotations

import multiprocessing
import os
import threading
from pathlib import Path

import pytest

from arshadow.video.chunks import STORE, ChunkStore
from arshadow.video.engine import EngineOptions


def _store(out, stem):
    return ChunkStore(out, stem, f"{stem:0>16}", EngineOptions())


def _is_parent(path) -> bool:
    return Path(path).name == STORE


def test_open_survives_the_parent_removed_between_its_two_mkdirs(tmp_path, monkeypatch):
    """Video b's join removes the empty shared folder right after video a's open created it and before
    a's own sub-folder is made: a's store is still made."""
    a, b = _store(tmp_path, "a"), _store(tmp_path, "b")
    real_mkdir = os.mkdir
    fired = []

    def mkdir(path, mode=0o777, *args, **kw):
        real_mkdir(path, mode, *args, **kw)
        if _is_parent(path) and not fired:
            fired.append(path)
            b.remove()  # the other video's join, in the window (its own folder is already gone)

    monkeypatch.setattr(os, "mkdir", mkdir)
    a.open()
    assert fired, "the window was not reached"
    assert a.dir.is_dir()
    a.record_path(0).write_text("{}")  # usable


def test_two_joins_removing_the_shared_folder_at_once_both_succeed(tmp_path, monkeypatch):
    """Both joins reach the removal of the (empty) shared folder at the same moment: neither raises."""
    a, b = _store(tmp_path, "a").open(), _store(tmp_path, "b").open()
    real_rmdir = os.rmdir
    barrier = threading.Barrier(2, timeout=1.0)

    def rmdir(path, *args, **kw):
        if _is_parent(path):
            try:
                barrier.wait()  # both removals are in their window: one will find the folder gone
            except threading.BrokenBarrierError:
                pass
        return real_rmdir(path, *args, **kw)

    monkeypatch.setattr(os, "rmdir", rmdir)
    errors = []

    def join(store):
        try:
            store.remove()
        except Exception as exc:  # noqa: BLE001 (collected: the test's failure)
            errors.append(exc)

    # both stores' own folders gone first (as when both joins are past their rmtree)
    import shutil

    shutil.rmtree(a.dir)
    shutil.rmtree(b.dir)
    ts = [threading.Thread(target=join, args=(s,)) for s in (a, b)]
    for t in ts:
        t.start()
    for t in ts:
        t.join(10)
    assert not errors, errors
    assert not (tmp_path / STORE).exists()


def test_a_join_leaves_a_store_being_created_whole(tmp_path, monkeypatch):
    """Video a's join finds the shared folder empty, and video b's store is created just before the
    removal: b's store stays and a's join raises nothing."""
    a, b = _store(tmp_path, "a").open(), _store(tmp_path, "b")
    real_rmdir = os.rmdir
    fired = []

    def rmdir(path, *args, **kw):
        if _is_parent(path) and not fired:
            fired.append(path)
            b.open()  # the other video's open, in the window
        return real_rmdir(path, *args, **kw)

    monkeypatch.setattr(os, "rmdir", rmdir)
    a.remove()
    assert fired, "the window was not reached"
    assert b.dir.is_dir() and not a.dir.exists()


def _hammer(out, stems, rounds, widen: bool) -> list:
    """Open, write a chunk record, remove: ``rounds`` times for each of ``stems`` at once (threads);
    ``widen``: a pause in every creation of the shared folder (the window of the race). Returns errors."""
    import time

    real_mkdir = os.mkdir
    if widen:

        def mkdir(path, mode=0o777, *args, **kw):
            real_mkdir(path, mode, *args, **kw)
            if _is_parent(path):
                time.sleep(0.002)

        os.mkdir = mkdir
    errors = []
    start = threading.Barrier(len(stems), timeout=10)

    def video(stem):
        try:
            start.wait()
            for k in range(rounds):
                s = _store(out, stem).open()
                s.record_path(k).write_text("{}")
                s.remove()
        except Exception as exc:  # noqa: BLE001 (collected)
            errors.append(f"{type(exc).__name__}: {exc}")

    try:
        ts = [threading.Thread(target=video, args=(s,)) for s in stems]
        for t in ts:
            t.start()
        for t in ts:
            t.join(60)
    finally:
        os.mkdir = real_mkdir
    return errors


def test_many_videos_opening_and_removing_at_once_threads(tmp_path):
    """8 videos x 40 chunk stores opened and removed at once (threads, the window widened): no error."""
    errors = _hammer(tmp_path, [f"v{i}" for i in range(8)], 40, widen=True)
    assert not errors, f"{len(errors)} failures, e.g. {errors[0]}"
    assert not (tmp_path / STORE).exists()


def _proc(out, stem, rounds, q):
    q.put(_hammer(out, [stem, stem + "x"], rounds, widen=True))


def test_many_videos_opening_and_removing_at_once_processes(tmp_path):
    """4 processes x 2 threads x 40 stores opened and removed at once: no error, nothing left."""
    ctx = multiprocessing.get_context("fork")
    q = ctx.Queue()
    ps = [ctx.Process(target=_proc, args=(tmp_path, f"p{i}", 40, q)) for i in range(4)]
    for p in ps:
        p.start()
    errors = []
    for _ in ps:
        errors += q.get(timeout=120)
    for p in ps:
        p.join(30)
    assert not errors, f"{len(errors)} failures, e.g. {errors[0]}"
    assert not (tmp_path / STORE).exists()


@pytest.mark.parametrize("n", [1, 3])
def test_make_folder_creates_nested_folders(tmp_path, n):
    from arshadow.io import make_folder

    p = tmp_path.joinpath(*[f"d{i}" for i in range(n)])
    assert make_folder(p) == p and p.is_dir()
    assert make_folder(p) == p  # already there: fine
