"""Python's cyclic garbage collector, run on the GUI thread only while a studio window is open.

CPython runs a collection in whichever thread happens to allocate when a
generation's threshold is crossed. In the studio that is often a worker
thread (loading a file, running a solver), and a collected reference cycle
may hold Qt or VTK objects of the GUI thread: their C++ destructors then run
on the worker thread, which crashes Qt/VTK (a segmentation fault, seen when
a closed window's plotters were collected during the next window's file
load). The remedy used by Qt applications (e.g. pyqtgraph, Orange) is to
switch automatic collection off and collect from a GUI-thread timer with the
same generation thresholds. :func:`collect_on_gui_thread` does that for as
long as one window holds it; when the last window releases it, a final
collection runs on the GUI thread and automatic collection is switched back
on, so non-GUI code in the same process (the test suite) is unaffected.
Automatic collection comes back only once no studio thread (a thread named
``corr-…``: jobs, the kernels' warm-up) is alive: the window being closed
becomes garbage right after its release, and a studio thread still running
would otherwise be the one that collects it. Until then the timer keeps
collecting here.
"""

from __future__ import annotations

import gc
import threading

from PySide6.QtCore import QObject, QTimer

CHECK_INTERVAL_MS = 500
#: name prefix of the threads the studio starts (:mod:`app.worker`, the warm-up of the compiled kernels)
STUDIO_THREAD_PREFIX = "corr-"


def studio_threads_alive() -> bool:
    """Whether a thread the studio started, other than the calling one, is still running."""
    current = threading.current_thread()
    return any(t is not current and t.name.startswith(STUDIO_THREAD_PREFIX) for t in threading.enumerate())


class GuiThreadCollector(QObject):
    """Collects the generations whose thresholds ``gc.get_count()`` has crossed, on a timer."""

    def __init__(self, parent: QObject | None = None):
        super().__init__(parent)
        self._timer = QTimer(self)
        self._timer.setInterval(CHECK_INTERVAL_MS)
        self._timer.timeout.connect(self._tick)
        self._holders: set[int] = set()
        self._enable_pending = False

    def hold(self, owner: QObject) -> None:
        """Switch automatic collection off while ``owner`` is alive (idempotent)."""
        if not self._holders:
            gc.disable()
            self._timer.start()
        self._enable_pending = False
        self._holders.add(id(owner))

    def release(self, owner: QObject) -> None:
        """Drop ``owner``'s hold; after the last release automatic collection comes back (see the module)."""
        if id(owner) not in self._holders:
            return
        self._holders.discard(id(owner))
        if not self._holders:
            self._enable_pending = True
            self._enable_when_safe()

    def _enable_when_safe(self) -> None:
        if self._holders or not self._enable_pending or studio_threads_alive():
            return  # the timer keeps collecting on this thread and tries again
        self._enable_pending = False
        self._timer.stop()
        gc.collect()
        gc.enable()

    def _tick(self) -> None:
        self.collect_due()
        self._enable_when_safe()

    def collect_due(self) -> int:
        """Collect the oldest generation whose count has reached its threshold (as CPython would)."""
        counts, thresholds = gc.get_count(), gc.get_threshold()
        for generation in (2, 1, 0):
            if counts[generation] > thresholds[generation]:
                return gc.collect(generation)
        return 0


_collector: GuiThreadCollector | None = None


def collect_on_gui_thread(owner: QObject) -> GuiThreadCollector:
    """The process's collector (created on first use, on the calling GUI thread), held by ``owner``."""
    global _collector
    if _collector is None:
        _collector = GuiThreadCollector()
    _collector.hold(owner)
    return _collector
