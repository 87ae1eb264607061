"""Ctrl-C and SIGTERM held back while a compiled library is imported (corrlib.interrupts)."""

import signal
import threading

import pytest

from corrlib.interrupts import signals_held


class Stop(BaseException):
    pass


def _raise_stop(signum, frame):
    raise Stop(signum)


@pytest.fixture(autouse=True)
def python_default_sigint():
    """Ctrl-C as Python sets it up in a foreground process. Python leaves SIGINT ignored where its parent
    ignored it (a suite started in the background by a non-interactive shell), and these tests interrupt
    themselves with it."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


@pytest.fixture
def sigterm_raises_stop():
    previous = signal.signal(signal.SIGTERM, _raise_stop)
    yield
    signal.signal(signal.SIGTERM, previous)


def _extension_init():
    """What a compiled module's initialisation does with an exception raised inside it (pybind11)."""
    try:
        signal.raise_signal(signal.SIGINT)
    except BaseException as exc:
        raise ImportError("initialization failed") from exc


def _import_optional_part() -> bool:
    """What matplotlib does with its 3D axes: an import error means the optional part is missing."""
    try:
        _extension_init()
    except Exception:
        return False
    return True


def test_without_holding_an_interrupt_inside_an_extensions_init_is_lost():
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    assert _import_optional_part() is False  # no KeyboardInterrupt reached us, and the part is missing


def test_a_held_interrupt_keeps_the_import_and_arrives_after_it():
    loaded = None
    with pytest.raises(KeyboardInterrupt):
        with signals_held():
            loaded = _import_optional_part()
    assert loaded is True
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_held_sigterm_goes_to_the_previous_python_handler(sigterm_raises_stop):
    reached_the_end = False
    with pytest.raises(Stop):
        with signals_held():
            signal.raise_signal(signal.SIGTERM)
            reached_the_end = True
    assert reached_the_end
    assert signal.getsignal(signal.SIGTERM) is _raise_stop


def test_an_interrupt_wins_over_an_error_of_the_block():
    with pytest.raises(KeyboardInterrupt) as caught:
        with signals_held():
            signal.raise_signal(signal.SIGINT)
            raise ValueError("the import failed")
    assert isinstance(caught.value.__context__, ValueError)


def test_without_a_signal_nothing_happens_and_the_handlers_are_restored(sigterm_raises_stop):
    with signals_held():
        value = 1 + 1
    assert value == 2
    assert signal.getsignal(signal.SIGTERM) is _raise_stop
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_an_ignored_signal_stays_ignored():
    previous = signal.signal(signal.SIGTERM, signal.SIG_IGN)
    try:
        with signals_held():
            signal.raise_signal(signal.SIGTERM)
        assert signal.getsignal(signal.SIGTERM) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGTERM, previous)


def test_outside_the_main_thread_it_changes_nothing():
    seen = []

    def worker():
        with signals_held():
            seen.append(signal.getsignal(signal.SIGINT))

    thread = threading.Thread(target=worker)
    thread.start()
    thread.join()
    assert seen == [signal.default_int_handler]


def test_the_pictures_import_registers_the_3d_axes():
    from matplotlib import projections

    from corrlib.plotting import preload

    preload()
    assert "3d" in projections.get_projection_names()


def test_pictures_are_drawn_whatever_backend_the_environment_names(tmp_path):
    """``MPLBACKEND=garbage`` (or a GUI backend on a machine without a display) gave a traceback after the
    computation; the pictures are drawn by an Agg canvas of their own, without pyplot."""
    import subprocess
    import sys

    code = ("import numpy as np; from corrlib.plotting import save_energy_trace; "
            f"save_energy_trace({str(tmp_path / 'c.png')!r}, np.linspace(3, 1, 20))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                          env={**__import__("os").environ, "MPLBACKEND": "garbage"})
    assert done.returncode == 0 and "Traceback" not in done.stderr and "MPLBACKEND='garbage'" in done.stderr
    assert (tmp_path / "c.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_ctrl_c_while_the_mesh_reader_is_imported_is_not_lost(tmp_path, monkeypatch):
    """trimesh catches BaseException around its optional imports; a Ctrl-C inside its import would vanish
    and the file would be read on. A stand-in module does what trimesh's import does with an interrupt."""
    import sys

    import trimesh  # noqa: F401  (loaded, so that the stand-in is replaced by it again after the test)

    from corrlib.io import load_mesh

    package = tmp_path / "fake" / "trimesh"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text(
        "import signal\n"
        "try:\n"
        "    signal.raise_signal(signal.SIGINT)  # a Ctrl-C during the import\n"
        "except BaseException:\n"
        "    pass  # what trimesh does around its optional parts\n"
        "def load(*args, **kwargs):\n"
        "    raise ValueError('the stand-in reads nothing')\n")
    monkeypatch.syspath_prepend(str(tmp_path / "fake"))
    monkeypatch.delitem(sys.modules, "trimesh")
    mesh_file = tmp_path / "shape.obj"
    mesh_file.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(KeyboardInterrupt):
        load_mesh(mesh_file)


def test_an_interrupt_while_the_outputs_move_into_place_leaves_the_whole_set(tmp_path, monkeypatch):
    """staged_output moves its files one by one: a Ctrl-C between two moves would leave part of the set."""
    import os

    import corrlib.io as io

    moves = []
    move = os.replace

    def replace(source, target):
        moves.append(target)
        if len(moves) == 2:
            signal.raise_signal(signal.SIGINT)  # the user presses Ctrl-C between the second and third move
        move(source, target)

    monkeypatch.setattr(io.os, "replace", replace)
    out = tmp_path / "out"
    with pytest.raises(KeyboardInterrupt):
        with io.staged_output(out) as stage:
            for name in ("a.txt", "b.txt", "c.txt", "d.txt"):
                (stage / name).write_text(name)
    assert sorted(p.name for p in out.iterdir()) == ["a.txt", "b.txt", "c.txt", "d.txt"]


def test_an_interrupt_during_the_moves_still_removes_what_the_set_replaces(tmp_path, monkeypatch):
    """A morph of 5 frames over one of 11, interrupted between two moves: the held interrupt was delivered
    before the earlier set's frames 5-10 were removed, which left them beside the new ones."""
    import os

    import corrlib.io as io

    out = tmp_path / "out"
    out.mkdir()
    for i in range(11):
        (out / f"frame_{i:03d}.off").write_text("earlier")
    moves = []
    move = os.replace

    def replace(source, target):
        moves.append(target)
        if len(moves) == 2:
            signal.raise_signal(signal.SIGINT)
        move(source, target)

    monkeypatch.setattr(io.os, "replace", replace)
    with pytest.raises(KeyboardInterrupt):
        with io.staged_output(out, replaces="frame_*.off") as stage:
            for i in range(5):
                (stage / f"frame_{i:03d}.off").write_text("new")
    assert sorted(p.name for p in out.iterdir()) == [f"frame_{i:03d}.off" for i in range(5)]
    assert all(p.read_text() == "new" for p in out.iterdir())
