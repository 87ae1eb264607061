"""Progress reports and cancellation, without any GUI dependency.

Solvers are generators that ``yield Progress(...)`` between steps and
``return`` their result. :func:`run` drives such a generator to completion
(scripts, tests, CLI); the studio wraps the same generator in a worker
thread. Compiled loops poll a :class:`CancelToken`.
"""

from __future__ import annotations

import resource
import threading
import time
from collections.abc import Callable, Generator
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from corrlib.errors import Cancelled

T = TypeVar("T")


@dataclass(frozen=True)
class Progress:
    """One progress report.

    Attributes
    ----------
    stage : str
        Short name of the current stage ("eigenpairs", "iteration 3", ...).
    fraction : float
        Overall completion in [0, 1], or a negative number when unknown.
    message : str
        Free text (energies, counts).
    """

    stage: str
    fraction: float = -1.0
    message: str = ""


class CancelToken:
    """Thread-safe cancellation flag shared between a caller and a solver.

    :attr:`flag` is a one-element ``int8`` array set to 1 on cancellation, so
    compiled (numba) loops can poll it without calling back into Python.
    """

    def __init__(self):
        self._event = threading.Event()
        self.flag = np.zeros(1, dtype=np.int8)

    def cancel(self) -> None:
        self.flag[0] = 1
        self._event.set()

    @property
    def cancelled(self) -> bool:
        return self._event.is_set()

    def raise_if_cancelled(self) -> None:
        """Raise :class:`~corrlib.errors.Cancelled` if :meth:`cancel` was called."""
        if self._event.is_set():
            raise Cancelled("the computation was cancelled")


def run(generator: Generator[Progress, None, T], callback: Callable[[Progress], None] | None = None,
        token: CancelToken | None = None) -> T:
    """Run a solver generator to completion and return its result.

    Parameters
    ----------
    generator
        Yields :class:`Progress`, returns the result.
    callback
        Called with every progress report.
    token
        Checked between steps; cancellation raises :class:`Cancelled`.
    """
    while True:
        if token is not None:
            token.raise_if_cancelled()
        try:
            report = next(generator)
        except StopIteration as stop:
            return stop.value
        if callback is not None:
            callback(report)


def scaled_progress(generator: Generator[Progress, None, T], low: float, high: float,
                    label: str = "") -> Generator[Progress, None, T]:
    """Re-yield a solver generator's reports with their fractions mapped into ``[low, high]``; return its result.

    For a solver that runs others one after the other (each reports 0 to 1 of its own work). Unknown
    fractions (negative) stay unknown; ``label`` prefixes the messages.
    """
    while True:
        try:
            report = next(generator)
        except StopIteration as stop:
            return stop.value
        fraction = low + (high - low) * report.fraction if report.fraction >= 0 else report.fraction
        message = f"{label}: {report.message}" if label and report.message else (label or report.message)
        yield Progress(report.stage, fraction, message)


class LatestReport:
    """A progress callback that keeps the last report of a run on another thread (``report``, None before the
    first) and its last known fraction (``fraction``), for the calling thread to relay
    (:func:`~corrlib.methods.kernel_matching.starts.both_starts`)."""

    def __init__(self):
        self.report: Progress | None = None
        self.fraction = 0.0

    def __call__(self, report: Progress) -> None:
        if report.fraction >= 0:
            self.fraction = report.fraction
        self.report = report


def paired_progress(generator: Generator[Progress, None, T], other: LatestReport) -> Generator[Progress, None, T]:
    """Re-yield a solver generator's reports with the fraction of the two runs' work done, ``(f + f_other) / 2``
    (``f_other`` the other run's last known fraction; an unknown fraction stays unknown), and return its result.
    Both runs' fractions only grow, so the combined one does too."""
    while True:
        try:
            report = next(generator)
        except StopIteration as stop:
            return stop.value
        fraction = (report.fraction + other.fraction) / 2 if report.fraction >= 0 else report.fraction
        yield Progress(report.stage, fraction, report.message)


def peak_rss_mb() -> float:
    """Peak resident memory of this process so far, in MB (Linux ``ru_maxrss`` is in kB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


class Stopwatch:
    """Named wall-clock timings: ``with sw("eigen"): ...`` accumulates into ``sw.times``."""

    def __init__(self):
        self.times: dict[str, float] = {}

    def __call__(self, name: str):
        return _Lap(self, name)


class _Lap:
    def __init__(self, watch: Stopwatch, name: str):
        self.watch, self.name = watch, name

    def __enter__(self):
        self.start = time.perf_counter()
        return self

    def __exit__(self, *exc):
        self.watch.times[self.name] = self.watch.times.get(self.name, 0.0) + time.perf_counter() - self.start
        return False
