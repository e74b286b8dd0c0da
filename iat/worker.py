"""One background thread that runs the newest request: the viewer's re-bakes and re-solves.

:class:`LatestWorker` owns the thread, the lock and the hand-over: a request made
while another is waiting replaces it (only the newest runs next), the worker
publishes results as they come, and the UI thread takes the newest one with
:meth:`~LatestWorker.poll` without ever blocking. Subclasses say how a request is
taken (:meth:`~LatestWorker._take`) and what it does (:meth:`~LatestWorker._work`);
:class:`iat.lighting.relight.Relighter` and ``viewer.bake_worker.BakeWorker`` are the two.

Between requests the thread may do optional work of its own (:meth:`~LatestWorker._idle`,
one small piece per call: the bake worker pre-warms the slider's neighbours there); a
request made meanwhile is taken as soon as that piece returns, and the piece may look at
:meth:`~LatestWorker._superseded` to return early.
"""

from __future__ import annotations

import threading
import time
from typing import Any


class LatestWorker:
    """A daemon thread that runs the newest pending request, one at a time.

    Subclasses set their own fields, then call ``super().__init__(name)`` (it starts the
    thread), put requests in ``self._pending`` under ``self._cv`` (see :meth:`_request`),
    and implement :meth:`_work`, which may call :meth:`_publish` any number of times.
    ``published`` counts the results published.
    """

    def __init__(self, name: str):
        self._cv = threading.Condition()
        self._pending: Any = None
        self._result: Any = None
        self._running = False
        self._stop = False
        self.published = 0
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)
        self._thread.start()

    # -- UI side ---------------------------------------------------------------------------------
    def _request(self, request: Any) -> None:
        """Make ``request`` the next one to run (replacing one not started yet)."""
        with self._cv:
            self._pending = request
            self._cv.notify_all()

    def poll(self) -> Any:
        """The newest published result not yet returned, or None."""
        with self._cv:
            r, self._result = self._result, None
            return r

    @property
    def busy(self) -> bool:
        """A request is running or waiting to run."""
        with self._cv:
            return self._running or self._pending is not None

    def wait(self, timeout: float = 60.0) -> bool:
        """Block until idle (tests and the benchmark); True when idle."""
        end = time.monotonic() + timeout
        with self._cv:
            while self._running or self._pending is not None:
                left = end - time.monotonic()
                if left <= 0:
                    return False
                self._cv.wait(left)
        return True

    @property
    def alive(self) -> bool:
        """The worker thread still runs (False once :meth:`close` has joined it)."""
        return self._thread.is_alive()

    def close(self, timeout: float = 30.0) -> None:
        """Stop the thread (after the request in progress, if any)."""
        with self._cv:
            self._stop = True
            self._pending = None
            self._cv.notify_all()
        self._thread.join(timeout)

    # -- worker side -----------------------------------------------------------------------------
    def _take(self) -> Any:
        """Take the pending request (called with the lock held, ``_pending`` not None)."""
        request, self._pending = self._pending, None
        return request

    def _work(self, request: Any) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _publish(self, result: Any) -> None:
        with self._cv:
            self._result = result
            self.published += 1
            self._cv.notify_all()

    def _superseded(self) -> bool:
        """A newer request is waiting, or the worker is closing: a long request may stop."""
        with self._cv:
            return self._pending is not None or self._stop

    def _idle(self) -> bool:
        """Optional work while no request waits (called without the lock, not counted as
        :attr:`busy`): do one small piece and return True to be called again, False when there
        is nothing to do (the thread then sleeps until the next request). Requests are taken
        between pieces, so a piece should be short or stop early when :meth:`_superseded`."""
        return False

    def _loop(self) -> None:
        while True:
            with self._cv:
                if self._stop:
                    return
                taken = self._pending is not None
                if taken:
                    request = self._take()
                    self._running = True
            if not taken:
                try:
                    more = self._idle()
                except Exception:  # idle work is optional: it never ends the thread
                    more = False
                if not more:
                    with self._cv:
                        while self._pending is None and not self._stop:
                            self._cv.wait()
                continue
            try:
                self._work(request)
            finally:
                with self._cv:
                    self._running = False
                    self._cv.notify_all()
