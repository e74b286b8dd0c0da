"""The gather threads (:class:`TaskPool`): a process-wide pool per thread count, shared by all
solves, that runs a solve's gathers two at a time so one's Python runs while the other's kernels
and rays do."""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor, wait

from iat.radiosity.kernels import one_thread
from iat.radiosity.visibility import Visibility

_POOLS: dict[int, ThreadPoolExecutor] = {}
_POOLS_LOCK = threading.Lock()
_IN_TASK = threading.local()


def _pool(n: int) -> ThreadPoolExecutor:
    """The process's pool of ``n`` gather threads (made once per ``n``, shared by all solves)."""
    with _POOLS_LOCK:
        if n not in _POOLS:
            _POOLS[n] = ThreadPoolExecutor(n, thread_name_prefix="iat-gather")
        return _POOLS[n]


def no_check() -> None:
    """A poll that never cancels (for work whose caller polls itself)."""


class TaskPool:
    """Runs a solve's tasks on :attr:`Visibility.threads` threads (``vis`` traces their rays)."""

    def __init__(self, vis: Visibility):
        self.vis = vis

    def imap(
        self, fn: Callable, items: Iterable, check: Callable[[], None], spread: bool = False
    ) -> Iterator:
        """``fn(item)`` for each item, in order, up to :attr:`Visibility.threads` at once: a gather
        spends most of its time in kernels and rays that release the GIL, so two of them keep
        both cores busy where one leaves a core idle during its Python. Results do not depend on
        the thread count. ``check()`` is polled while waiting; when it raises, the tasks not
        started are dropped, the running ones finish, and the exception propagates. With one
        item or one thread, or inside a task, it runs in the calling thread (whose kernels and
        rays may then use every thread). ``spread``: each task's kernels and rays use every
        thread too (:meth:`traced_map`), else the task's own thread alone."""
        threads = self.vis.threads
        items = list(items)
        in_task = getattr(_IN_TASK, "active", False)
        if threads <= 1 or len(items) <= 1 or in_task:
            for item in items:
                yield fn(item)
                if not in_task:  # (progress is reported from the solve's thread only)
                    check()
            return
        pool, pending, queued = _pool(threads), [], items[::-1]
        try:
            while pending or queued:
                while queued and len(pending) < 2 * threads:
                    pending.append(pool.submit(self._task, fn, queued.pop(), spread))
                while not wait(pending[:1], timeout=0.05).done:
                    check()
                yield pending.pop(0).result()
        finally:
            for f in pending:
                f.cancel()
            wait(pending)

    def traced_map(self, fn: Callable, items: Iterable, check: Callable[[], None]) -> Iterator:
        """:meth:`imap` of tasks whose rays are traced by kernels that spread over the threads
        themselves (Embree's C API: :meth:`Visibility.embree_args`; a group's shots, stage C's
        sources): two at once, each kernel on every thread (numba's OpenMP layer runs a team per
        calling thread, and the cores are shared), so that one task's Python still runs while the
        other's rays do, and a long task beside a short one keeps both cores once the short one is
        done (docs/benchmarks.md, "Each shot's kernel on every thread"). With embreex, :meth:`imap`."""
        return self.imap(fn, items, check, spread=self.vis.embree_args() is not None)

    def _task(self, fn: Callable, item, spread: bool = False):
        """``fn(item)`` on a gather thread: its kernels and rays run on this thread alone (the
        other tasks have the other cores) unless ``spread``, and it runs any :meth:`imap` of its
        own in order."""
        _IN_TASK.active = True
        try:
            if spread:
                return fn(item)
            with one_thread(), self.vis.on_this_thread():
                return fn(item)
        finally:
            _IN_TASK.active = False
