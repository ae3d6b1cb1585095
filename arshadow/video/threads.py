"""The engine's thread plumbing: a worker thread that keeps its exception, and a queue put that gives up
when the run stops."""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable

__all__ = ["END", "Worker", "put_or_stop"]

#: end-of-stream marker put on a queue after the last item
END = object()


class Worker(threading.Thread):
    """A daemon thread running ``target()``; an exception it raises is kept in :attr:`error` for the main
    thread to re-raise."""

    def __init__(self, target: Callable[[], object], name: str) -> None:
        super().__init__(name=name, daemon=True)
        self._target_fn = target
        self.error: BaseException | None = None

    def run(self) -> None:
        try:
            self._target_fn()
        except BaseException as exc:  # noqa: BLE001 (handed to the main thread, re-raised there)
            self.error = exc


def put_or_stop(q: queue.Queue[object], item: object, stop: threading.Event) -> bool:
    """Put ``item`` on the bounded queue ``q``, waiting while it is full; False if ``stop`` is set first."""
    while not stop.is_set():
        try:
            q.put(item, timeout=0.1)
            return True
        except queue.Full:
            continue
    return False
