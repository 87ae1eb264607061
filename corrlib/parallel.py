"""Running independent jobs (meshes of a collection, pairs of a benchmark) in parallel.

Local process pools by default. Workers limit BLAS to one thread each (the
pool already uses the cores; two multi-threaded BLAS per core collapse).
"""

from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor


def _limit_threads():
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)


def process_pool(jobs: int | None = None) -> ProcessPoolExecutor:
    """A process pool with ``jobs`` workers (default: all cores).

    Workers start from a fork server: forking the caller directly is unsafe
    once numba's OpenMP threads or the studio's threads run in it. As with
    any non-fork start method, a script that uses the pool must guard its
    entry point with ``if __name__ == "__main__":``.
    """
    jobs = jobs or os.cpu_count() or 1
    return ProcessPoolExecutor(max_workers=jobs, initializer=_limit_threads,
                               mp_context=multiprocessing.get_context("forkserver"))
