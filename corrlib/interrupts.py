"""Holding Ctrl-C and SIGTERM back while a compiled library is imported.

Python runs a signal's handler between two bytecodes of the main thread, so
the ``KeyboardInterrupt`` (or the command line's ``Terminated``) is raised
wherever that thread happens to be. Inside the initialisation of a compiled
extension module that is a problem: the extension's init code catches the
exception and reports an ``ImportError`` instead (pybind11 modules do), and
a library that treats an import error as a missing optional part goes on
without it. Matplotlib does this for its 3D axes: a Ctrl-C that arrives
while ``matplotlib.pyplot`` is first imported is lost, and the picture
written next fails with "'3d' is not a valid value for projection". Some
libraries catch ``BaseException`` around their optional imports (trimesh),
which loses the interrupt outright.

:func:`signals_held` records SIGINT and SIGTERM during such an import and
delivers them to their previous handlers as soon as it is over.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

#: the signals held back: an interactive interrupt, a polite termination and a closed terminal
HELD_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


@contextmanager
def signals_held() -> Iterator[None]:
    """Hold SIGINT, SIGTERM and SIGHUP until the block ends, then deliver the first one that came.

    Only the main thread receives signals, so elsewhere this does nothing.
    A held signal is delivered to the handler that was installed before the
    block, also where the block raised: a Python handler is called (e.g.
    ``default_int_handler`` raises ``KeyboardInterrupt``), the default action
    is taken by raising the signal again, an ignored signal stays ignored.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []
    previous = {}
    try:
        for signum in HELD_SIGNALS:
            if signal.getsignal(signum) is not None:  # a handler set outside Python could not be put back
                previous[signum] = signal.signal(signum, lambda number, frame: received.append(number))
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        if received:  # also where the block failed: the interrupt is what the user asked for
            _deliver(received[0], previous[received[0]])


def _deliver(signum: int, handler) -> None:
    """Act on a held signal as its handler would have."""
    if callable(handler):
        handler(signum, None)
    elif handler == signal.SIG_DFL:
        signal.raise_signal(signum)
    # SIG_IGN: nothing to do
