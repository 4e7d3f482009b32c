"""The fleet transport's worker threads (`gmmap.fleet.net.transport`): Zenoh's callback threads
must never be blocked for long, so they hand each event to a queue that a worker runs in order.
"""

from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Callable
from typing import Any

# The transport's logger: these threads run the transport's callbacks, so their failures are
# the transport's to report (one logger to configure).
log = logging.getLogger("gmmap.fleet.net.transport")

_STOP = object()


class Worker:
    """A daemon thread running queued calls in order; a failing call is logged, never fatal."""

    def __init__(self, name: str) -> None:
        self._queue: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def submit(self, fn: Callable[..., Any], *args: Any) -> None:
        self._queue.put((fn, args))

    def stop(self, timeout: float = 5.0) -> None:
        self._queue.put(_STOP)
        # A callback that closes the transport runs on this very thread: joining would deadlock.
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout)

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is _STOP:
                return
            fn, args = item
            try:
                fn(*args)
            except Exception:
                log.exception("gmmap transport callback %r failed", fn)


def call_logged(callback: Callable[..., Any], *args: Any) -> None:
    try:
        callback(*args)
    except Exception:
        log.exception("gmmap transport: callback %r failed", callback)
