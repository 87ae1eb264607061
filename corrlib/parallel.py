"""Running independent jobs (meshes of a collection, pairs of a benchmark) in parallel.

Local process pools by default. Workers limit BLAS to one thread each,
numba to their share of the cores, and the methods' side threads to that
share too (:mod:`corrlib.cores`): the pool already uses the cores, and two
multi-threaded BLAS per core collapse.
"""

from __future__ import annotations

import multiprocessing
import numbers
import os
from concurrent.futures import ProcessPoolExecutor

from corrlib.cores import set_core_share
from corrlib.errors import Cancelled, CorrError, InputError, ParameterError


def _limit_threads(share: int):
    import numba
    from threadpoolctl import threadpool_limits

    share = set_core_share(share)
    threadpool_limits(1)
    numba.set_num_threads(min(share, numba.config.NUMBA_NUM_THREADS))  # share >= 1


def process_pool(jobs: int | None = None, share: int | None = None) -> ProcessPoolExecutor:
    """A process pool with ``jobs`` workers (default: all cores), each limited to ``share`` cores (default: its
    share of the machine; ``corr perf bench`` runs one worker on one core as the serial baseline).

    Workers start from a fork server: forking the caller directly is unsafe
    once numba's OpenMP threads or the studio's threads run in it. As with
    any non-fork start method, a script that uses the pool must guard its
    entry point with ``if __name__ == "__main__":``.
    """
    jobs = jobs or os.cpu_count() or 1
    _check_socket_folder()
    return ProcessPoolExecutor(max_workers=jobs, initializer=_limit_threads,
                               initargs=(share or (os.cpu_count() or 1) // jobs,),
                               mp_context=multiprocessing.get_context("forkserver"))


#: the longest path of a Unix socket (Linux's ``sun_path``, without its final zero byte), and the length the fork
#: server's socket adds to the temporary folder (``/pymp-`` and ``/listener-``, each with 8 random characters)
UNIX_SOCKET_PATH_MAX, FORK_SERVER_SOCKET_NAME = 107, 32


def _check_socket_folder() -> None:
    """:class:`InputError` naming ``TMPDIR`` where the fork server's socket would not fit in a Unix socket path
    (the pool failed later with "AF_UNIX path too long", naming neither)."""
    import sys
    import tempfile

    folder = tempfile.gettempdir()
    if sys.platform.startswith("linux") and \
            len(os.fsencode(folder)) + FORK_SERVER_SOCKET_NAME > UNIX_SOCKET_PATH_MAX:
        raise InputError(f"the temporary folder {folder} (TMPDIR) is too long a path for the worker processes' "
                         f"socket (at most {UNIX_SOCKET_PATH_MAX - FORK_SERVER_SOCKET_NAME} bytes); set TMPDIR to a "
                         "shorter path")


def check_jobs(jobs) -> None:
    """:class:`ParameterError` unless ``jobs`` is 0 or None (all cores) or a positive whole number of worker
    processes."""
    if jobs is not None and (isinstance(jobs, bool) or not isinstance(jobs, numbers.Integral) or jobs < 0):
        raise ParameterError(f"jobs must be 0 or None (all cores) or a positive whole number of worker processes, "
                             f"got {jobs!r}")


class job_executor:
    """Context manager: a local process pool, or Dask's ``concurrent.futures`` executor on a cluster.

    ``with job_executor(jobs, scheduler) as pool: pool.submit(fn, ...)``: the
    benchmark runner and retrieval use this one code path; ``scheduler`` is
    the address of a running Dask scheduler (``tcp://host:8786``), ``None``
    for ``jobs`` local processes.
    """

    def __init__(self, jobs: int | None, scheduler: str | None):
        check_jobs(jobs)
        if scheduler is not None:
            check_scheduler_address(scheduler)
        self.jobs, self.scheduler = jobs, scheduler
        self.client = None

    def __enter__(self):
        if self.scheduler is None:
            self.pool = process_pool(self.jobs)
            return self.pool
        try:
            from distributed import Client
        except ImportError:
            raise CorrError("--scheduler needs Dask: pip install 'corrlib[dist]'") from None
        try:
            self.client = Client(self.scheduler, timeout=10)
        except OSError as exc:
            raise CorrError(f"cannot reach the Dask scheduler {self.scheduler}: {exc}") from None
        self.pool = self.client.get_executor(pure=False)
        return self.pool

    def __exit__(self, exc_type, exc, tb):
        # Ctrl-C, SIGTERM, exit, a closed generator, or the user's cancel: nobody waits for the running jobs
        interrupted = exc_type is not None and (not issubclass(exc_type, Exception) or issubclass(exc_type, Cancelled))
        if interrupted and self.client is not None:
            self.pool.shutdown(wait=False)  # Dask's executor cancels the cluster's futures instead of waiting
        elif interrupted:
            # stop the local workers now instead of waiting for their jobs (else they outlive the command, and a
            # cancelled retrieval in the studio waits for the meshes in progress)
            workers = list((getattr(self.pool, "_processes", None) or {}).values())
            self.pool.shutdown(wait=False, cancel_futures=True)
            for worker in workers:
                worker.terminate()
        self.pool.shutdown(wait=True)  # a no-op after the above
        if self.client is not None:
            self.client.close()
        return False


def check_scheduler_address(address) -> str:
    """A Dask scheduler address ``[protocol://]host:port``, checked before any work (ParameterError otherwise)."""
    import re

    text = str(address).strip()
    match = re.fullmatch(r"(?:(?:tcp|tls|ws|wss|ucx)://)?(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9._-]+):(\d{1,5})/?", text)
    if match is None or not 0 < int(match.group(2)) < 65536:
        raise ParameterError(f"--scheduler {address!r} is not a Dask scheduler address; expected "
                             f"[tcp://]host:port, e.g. tcp://127.0.0.1:8786")
    return text
