"""A studio window for the GUI tests (imported by ``test_studio*.py`` and the
``window`` fixture of ``conftest.py`` only: it needs Qt).

The tests' widgets are closed at the end of their test and never deleted (``conftest.py`` ends the process
without destructors): deleting a closed studio window, i.e. its VTK render windows, under Xvfb crashed the
test process now and then (docs/decisions.md), while the studio itself deletes its window only at exit.
"""

from PySide6.QtCore import QSettings

from app.main_window import MainWindow

#: widgets of the running test, closed by ``conftest.py`` when it ends
OPEN_WIDGETS: list = []
#: every closed widget of the session, kept alive until the process ends
CLOSED_WIDGETS: list = []


def keep_widget(widget):
    """Register a widget to be closed at the end of the test, never deleted (instead of ``qtbot.addWidget``)."""
    OPEN_WIDGETS.append(widget)
    return widget


def close_open_widgets() -> None:
    """Close the running test's widgets and keep them."""
    while OPEN_WIDGETS:
        widget = OPEN_WIDGETS.pop()
        widget.close()
        widget.hide()
        CLOSED_WIDGETS.append(widget)


def make_window(qtbot, ini_path, interactive=False, show=True):
    """A studio window with its own settings file (no state shared between tests)."""
    win = MainWindow(settings=QSettings(str(ini_path), QSettings.IniFormat), interactive=interactive)
    keep_widget(win)
    if show:
        win.show()
        qtbot.waitExposed(win)
    return win


def wait_loaded(qtbot, win, timeout=60_000):
    """Files load in the worker: wait until the window's load queue is empty."""
    qtbot.waitUntil(lambda: not win.is_loading(), timeout=timeout)
