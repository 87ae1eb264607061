"""Running solver generators in a worker thread with progress, cancellation and job ids.

Workers hand back numpy results only; every Qt/VTK object is built on the GUI
thread by the slots connected to :class:`JobRunner`'s signals. Starting a job
with the id of a running one supersedes it: the old one is cancelled and its
late signals are dropped (the runner only forwards signals of the job that
is current for its id).

Jobs run on plain daemon threads, not superqt's ``thread_worker``: that runs
on Qt's global thread pool (as many threads as cores, so a third job would
wait), its non-daemon threads keep the process alive until a solver stops,
and its abort works only at a ``yield`` — the supersession by key, the
:class:`CancelToken` polled inside compiled loops and the bounded
:meth:`JobRunner.shutdown` would all still be needed on top.
"""

from __future__ import annotations

import threading
import time
import traceback
from collections.abc import Callable, Generator

from PySide6.QtCore import QObject, Signal

from app.gui_gc import STUDIO_THREAD_PREFIX
from corrlib.errors import Cancelled, CorrError
from corrlib.progress import CancelToken, Progress

SHUTDOWN_TIMEOUT_S = 10.0  # closing the window waits this long for cancelled jobs to stop


class _Job:
    def __init__(self, key: str, serial: int, factory: Callable[[CancelToken], Generator]):
        self.key, self.serial, self.factory = key, serial, factory
        self.token = CancelToken()
        self.thread: threading.Thread | None = None
        self.started = time.perf_counter()


class JobRunner(QObject):
    """Runs generators ``factory(token) -> Generator[Progress, None, result]`` in threads.

    Signals carry the job key (e.g. ``"pair"``, ``"retrieval"``) so a view
    can supersede its own job without touching the others.
    """

    progress = Signal(str, object)  # key, Progress
    finished = Signal(str, object)  # key, result
    failed = Signal(str, str)  # key, message
    cancelled = Signal(str)
    _relay = Signal(str, int, str, object)  # key, serial, kind, payload (thread -> GUI thread)

    def __init__(self, parent=None):
        super().__init__(parent)
        self._jobs: dict[str, _Job] = {}
        self._serial = 0
        self._relay.connect(self._on_relay)

    def start(self, key: str, factory: Callable[[CancelToken], Generator]) -> int:
        """Start a job under ``key``, cancelling the previous job with that key."""
        self.cancel(key)
        self._serial += 1
        job = _Job(key, self._serial, factory)
        self._jobs[key] = job
        job.thread = threading.Thread(target=self._run, args=(job,), name=f"{STUDIO_THREAD_PREFIX}job-{key}",
                                      daemon=True)
        job.thread.start()
        return job.serial

    def _run(self, job: _Job) -> None:
        try:
            gen = job.factory(job.token)
            while True:
                job.token.raise_if_cancelled()
                try:
                    report = next(gen)
                except StopIteration as stop:
                    self._relay.emit(job.key, job.serial, "finished", stop.value)
                    return
                self._relay.emit(job.key, job.serial, "progress", report)
        except Cancelled:
            self._relay.emit(job.key, job.serial, "cancelled", None)
        except CorrError as exc:
            self._relay.emit(job.key, job.serial, "failed", str(exc))
        except Exception as exc:  # a bug: show it, keep the studio alive
            self._relay.emit(job.key, job.serial, "failed",
                             f"unexpected error: {exc}\n\n{traceback.format_exc(limit=6)}")

    def _on_relay(self, key: str, serial: int, kind: str, payload) -> None:
        job = self._jobs.get(key)
        if job is None or job.serial != serial:
            return  # a superseded job: drop its late signals
        if kind == "progress":
            self.progress.emit(key, payload)
            return
        del self._jobs[key]
        if kind == "finished":
            self.finished.emit(key, payload)
        elif kind == "failed":
            self.failed.emit(key, payload)
        else:
            self.cancelled.emit(key)

    def cancel(self, key: str) -> None:
        """Ask the job under ``key`` to stop (it stops at its next progress report)."""
        job = self._jobs.get(key)
        if job is not None:
            job.token.cancel()

    def is_running(self, key: str) -> bool:
        return key in self._jobs

    def elapsed(self, key: str) -> float:
        job = self._jobs.get(key)
        return time.perf_counter() - job.started if job else 0.0

    def shutdown(self, timeout: float = SHUTDOWN_TIMEOUT_S) -> None:
        """Cancel every job and wait for the threads (called when the window closes)."""
        jobs = list(self._jobs.values())
        for job in jobs:
            job.token.cancel()
        deadline = time.perf_counter() + timeout
        for job in jobs:
            if job.thread is not None:
                job.thread.join(max(0.0, deadline - time.perf_counter()))
        self._jobs.clear()


def progress_text(report: Progress) -> str:
    return f"{report.stage}: {report.message}" if report.message else report.stage
