"""Two runs of the solver side by side on the two cores (:func:`side_by_side`): the two starts of
``init="best"`` and the two landmark runs of stage 9.
"""

from __future__ import annotations

from concurrent.futures import wait

from corrlib.cores import InlineExecutor, side_threads
from corrlib.errors import Cancelled, CorrError
from corrlib.methods.kernel_matching.state import KernelState
from corrlib.progress import CancelToken, LatestReport, Progress, paired_progress, run, scaled_progress


#: seconds between checks of the caller's cancellation while one start waits for the other
#: (:func:`~.starts.both_starts`)
WAIT_POLL = 0.1


def or_its_error(solver):
    """A solver generator that returns its :class:`~corrlib.errors.CorrError` instead of raising it (a
    cancellation is still raised): the second start's failure leaves the first start's map
    (:func:`~.starts.best_of_both_starts`)."""
    try:
        return (yield from solver)
    except Cancelled:
        raise
    except CorrError as exc:
        return exc


def side_by_side(first: KernelState, second: KernelState, run_first, run_second, labels: tuple[str, str]):
    """Two runs of the solver, ``run_first(first)`` in the calling thread (its progress reported) and
    ``run_second(second)`` on a thread beside it where this process may use two cores, else after it. A
    generator; returns both results, the second run's being its :class:`~corrlib.errors.CorrError` if it failed
    (the first run's errors, and a cancellation, are raised).

    After the spectra the solver keeps one core busy (assignments, score products, cells), so the second
    run costs no wall time on two cores, provided that BLAS does not spread either run over both cores
    as well: within the two runs it is limited to one thread (the same maps; sums may differ in the last bit).
    The second run has its own cancel token, set when the first ends in any way (the caller's
    cancellation included), so that neither an error nor a cancellation waits for the second run. Side by side,
    the fraction reported is that of both runs' work (:func:`~corrlib.progress.paired_progress`); once the first
    has ended, each report of the second is relayed once, labelled.
    """
    from threadpoolctl import threadpool_limits

    with side_threads(1) as pool:
        if isinstance(pool, InlineExecutor):  # one core's share: one run after the other
            mine = yield from scaled_progress(run_first(first), 0.0, 0.5, labels[0])
            theirs = yield from scaled_progress(or_its_error(run_second(second)), 0.5, 1.0, labels[1])
            return mine, theirs
        caller, second.token = second.token, CancelToken()
        latest = LatestReport()
        try:
            with threadpool_limits(1):
                other = pool.submit(run, or_its_error(run_second(second)), latest, second.token)
                yield Progress("kernel matching", 0.0, f"{labels[1]} runs beside this one, on the other core")
                mine = yield from paired_progress(scaled_progress(run_first(first), 0.0, 1.0, labels[0]), latest)
                relayed = None
                while not wait([other], timeout=WAIT_POLL).done:
                    caller.raise_if_cancelled()
                    report = latest.report
                    if report is not relayed:  # each of its reports once, not one per poll
                        relayed = report
                        yield Progress(report.stage, (1.0 + latest.fraction) / 2,
                                       f"{labels[1]}: {report.message}" if report.message else labels[1])
                theirs = other.result()
        finally:
            second.token.cancel()  # a finished run ignores it; a running one stops at its next check
    return mine, theirs
