"""Dask worker preload (``dask worker --preload tests/dask_widen.py``): widens the window of the chunk-store
race (the cluster and flags work) on real worker processes, so that a test sees it in every run instead of one in nine.

- after a video's join removes its own chunk folder, it waits (up to :data:`WAIT_S`) until the shared
  ``OUT/.arshadow-chunks`` holds no other video's folder: the joins of two videos then go on together;
- a removal of the shared folder waits :data:`RMDIR_DELAY_S` first: the other join, meanwhile, finds the
  folder still there (and empty), and removes it too.

For a batch of two videos on two worker processes (a join waiting holds its worker: with more videos than
workers the joins would wait for chunks that cannot run, up to :data:`WAIT_S`).
"""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path

WAIT_S = 60.0
RMDIR_DELAY_S = 0.5
SHARED = ".arshadow-chunks"
#: the unpatched functions (Dask may load a preload more than once in a process)
_real_rmtree = getattr(shutil.rmtree, "real", shutil.rmtree)
_real_rmdir = getattr(os.rmdir, "real", os.rmdir)


def _rmtree(path, *args, **kw):
    _real_rmtree(path, *args, **kw)
    parent = Path(path).parent
    if parent.name != SHARED:
        return
    t0 = time.time()
    while time.time() - t0 < WAIT_S:
        try:
            if not os.listdir(parent):
                return
        except FileNotFoundError:
            return
        time.sleep(0.002)


def _rmdir(path, *args, **kw):
    if Path(path).name == SHARED:
        time.sleep(RMDIR_DELAY_S)
    return _real_rmdir(path, *args, **kw)


_rmtree.real = _real_rmtree
_rmdir.real = _real_rmdir
shutil.rmtree = _rmtree
os.rmdir = _rmdir


def dask_setup(worker):  # noqa: ARG001 (the preload hook Dask calls)
    pass
