"""A studio window for the GUI tests (imported by ``test_studio*.py`` and the
``window`` fixture of ``conftest.py`` only: it needs Qt)."""

from PySide6.QtCore import QSettings

from app.main_window import MainWindow


def make_window(qtbot, ini_path, interactive=False, show=True):
    """A studio window with its own settings file (no state shared between tests)."""
    win = MainWindow(settings=QSettings(str(ini_path), QSettings.IniFormat), interactive=interactive)
    qtbot.addWidget(win)
    if show:
        win.show()
        qtbot.waitExposed(win)
    return win


def wait_loaded(qtbot, win, timeout=60_000):
    """Files load in the worker: wait until the window's load queue is empty."""
    qtbot.waitUntil(lambda: not win.is_loading(), timeout=timeout)
