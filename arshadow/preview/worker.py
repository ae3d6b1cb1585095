"""One worker thread that runs the newest request only: a request still waiting when a newer one comes is
dropped (answered :class:`Superseded`), so no work queues behind a stale drag position.

The thread owns whatever its job function touches (the preview's :class:`arshadow.frame.session.Session` and its
OpenGL context live on it: a GL context is current on one thread).

Examples
--------
>>> w = LatestWins(lambda x: x * 2)
>>> w.submit(21).result(timeout=10)
42
>>> w.close()
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any

__all__ = ["LatestWins", "Superseded"]


class Superseded(Exception):
    """A request dropped unrun because a newer one came while it waited."""


class LatestWins:
    """Run ``job(request)`` on one thread, newest request first; older waiting ones are dropped.

    Parameters
    ----------
    job : callable
        ``job(request) -> result``, run on the worker thread only.
    on_stop : callable, optional
        Run on the worker thread after the last job (releases thread-bound resources: the GL context).
    """

    def __init__(
        self,
        job: Callable[[Any], Any],
        on_stop: Callable[[], None] | None = None,
    ) -> None:
        self._job, self._on_stop = job, on_stop
        self._cv = threading.Condition()
        self._pending: tuple[Any, Future] | None = None
        self._stopped = False
        #: requests dropped unrun so far
        self.dropped = 0
        self._thread = threading.Thread(target=self._loop, name="arshadow-preview-render", daemon=True)
        self._thread.start()

    def submit(self, request: Any) -> Future:
        """Queue ``request`` (replacing a waiting one, which gets :class:`Superseded`); a Future of its result."""
        fut: Future = Future()
        with self._cv:
            if self._stopped:
                fut.set_exception(Superseded("the preview is stopping"))
                return fut
            if self._pending is not None:
                self._pending[1].set_exception(Superseded("superseded by a newer request"))
                self.dropped += 1
            self._pending = (request, fut)
            self._cv.notify()
        return fut

    def _loop(self) -> None:
        try:
            while True:
                with self._cv:
                    while self._pending is None and not self._stopped:
                        self._cv.wait()
                    if self._stopped:
                        break
                    assert self._pending is not None
                    request, fut = self._pending
                    self._pending = None
                if not fut.set_running_or_notify_cancel():
                    continue
                try:
                    fut.set_result(self._job(request))
                except BaseException as exc:  # noqa: BLE001 (handed to the waiting request)
                    fut.set_exception(exc)
        finally:
            if self._on_stop is not None:
                self._on_stop()

    def close(self, timeout: float = 10.0) -> None:
        """Stop the thread after the job running now (a waiting request gets :class:`Superseded`)."""
        with self._cv:
            self._stopped = True
            if self._pending is not None:
                self._pending[1].set_exception(Superseded("the preview is stopping"))
                self._pending = None
            self._cv.notify()
        self._thread.join(timeout)
