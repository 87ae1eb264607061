"""The cores a process may keep busy, and threads beside the calling one that follow them.

A process pool's worker (:func:`corrlib.parallel.process_pool`) shares the
machine with the other workers: its initializer records the worker's share
(:func:`set_core_share`) and limits BLAS and numba to it. The methods' own
side threads (work beside the calling thread on kernels that release the
GIL) follow the same share through :func:`side_threads`.
"""

from __future__ import annotations

import os
from concurrent.futures import Executor, Future, ThreadPoolExecutor

#: the cores this process may keep busy, where a pool's initializer set it; None: every core of the machine
_core_share: int | None = None


def set_core_share(share: int) -> int:
    """Record this process's share of the cores (at least one; a pool with more workers than cores gives 0)
    and return it."""
    global _core_share
    _core_share = max(1, int(share))
    return _core_share


def core_share() -> int:
    """The cores this process may keep busy: a pool worker's share of the machine, every core elsewhere."""
    return _core_share or os.cpu_count() or 1


class InlineExecutor(Executor):
    """An executor that runs every call in the calling thread: ``submit`` at once, returning a finished future
    (its exception, if it raised, comes out of ``result()``, as from a thread); ``map`` lazily, each call when
    its result is asked for, so that no more than one result is held at a time (a thread pool's ``map`` holds
    only those its threads are ahead by; computing them all first would hold every one)."""

    def submit(self, fn, /, *args, **kwargs) -> Future:
        future = Future()
        try:
            future.set_result(fn(*args, **kwargs))
        except BaseException as exc:  # noqa: BLE001 - handed to the caller through the future, as a thread would
            future.set_exception(exc)
        return future

    def map(self, fn, *iterables, timeout=None, chunksize=1):
        return (fn(*args) for args in zip(*iterables))


def side_threads(max_workers: int) -> Executor:
    """Threads for work beside the calling thread (kernels that release the GIL), or none.

    A :class:`~concurrent.futures.ThreadPoolExecutor` of ``max_workers`` threads where this process may use
    more than one core (:func:`core_share`); an :class:`InlineExecutor` in a worker with one core's share,
    where threads would only take turns on that core, each evicting the other's data from its caches
    (``docs/decisions.md``). The results are the same either way; only the order of the work changes.
    """
    return ThreadPoolExecutor(max_workers=max_workers) if core_share() > 1 else InlineExecutor()
