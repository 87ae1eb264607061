"""The studio computes in its worker: loading, error reports and view data are jobs, the slots only draw.

GUI tests under a virtual X server (pytest-xvfb, Qt's xcb platform), like ``test_studio.py``.
"""

import ast
import os
import threading
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("QT_QPA_PLATFORM", "xcb")
pytest.importorskip("pyvistaqt")

from _data import ROOT, TOSCA  # noqa: E402
from _studio import keep_widget, make_window, wait_loaded  # noqa: E402

APP = Path(__file__).resolve().parents[1] / "app"
MAX_FUNCTION_LINES = 80


def run_and_wait(qtbot, win, method, timeout=180_000):
    with qtbot.waitSignal(win.result_ready, timeout=timeout) as blocker:
        win.run_method(method=method)
    return blocker.args[0]


def on_gui_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def recording(calls, func):
    """``func`` that appends to ``calls`` whether it runs on the GUI (main) thread."""

    def wrapper(*args, **kwargs):
        calls.append(on_gui_thread())
        return func(*args, **kwargs)

    return wrapper


@pytest.mark.slow
def test_error_report_and_spectrum_are_computed_in_the_worker(qtbot, window, monkeypatch):
    import corrlib.evaluation
    import corrlib.geometry.spectrum
    from app.views.pair import MODES

    error_calls, spectrum_calls = [], []
    monkeypatch.setattr(corrlib.evaluation, "geodesic_errors",
                        recording(error_calls, corrlib.evaluation.geodesic_errors))
    monkeypatch.setattr(corrlib.geometry.spectrum, "mesh_spectrum",
                        recording(spectrum_calls, corrlib.geometry.spectrum.mesh_spectrum))
    window.load_demo()
    wait_loaded(qtbot, window)
    assert window.gt is not None  # the demo pair's identity ground truth
    payloads = []
    window.runner.finished.connect(lambda key, payload: payloads.append((key, payload)))
    result = run_and_wait(qtbot, window, "descriptor-nn")
    assert error_calls == [False]  # measured once, in the worker
    key, outcome = payloads[-1]
    assert key == "pair" and outcome.result is result
    assert outcome.report is not None and outcome.errors.n_unmatched == 0  # the slot got a ready report
    assert outcome.function is not None and outcome.function.shape == (window.source.n_vertices,)
    assert "mean geodesic error" in window.pair_view.info.text()
    for mode in MODES:  # redrawing computes nothing: no error report, no spectrum on the GUI thread
        window.pair_view.mode.setCurrentText(mode)
    assert error_calls == [False]
    assert spectrum_calls and not any(spectrum_calls)
    assert window.pair_view.target_colors is None or window.pair_view.target_colors.shape[1] == 3


def fake_solver(unmatched_every: int):
    """A ``solve_iter`` stand-in: the identity map with every ``unmatched_every``-th vertex unmatched (-1)."""
    from corrlib.methods.base import MatchResult
    from corrlib.progress import Progress

    def solve_iter(name, source, target, params=None, token=None, **_kw):
        yield Progress("fake", 0.5)
        map_xy = np.arange(source.n_vertices)
        map_xy[::unmatched_every] = -1
        map_yx = np.arange(target.n_vertices)
        map_yx[::unmatched_every] = -1
        return MatchResult(name, map_xy, map_yx, 0.0, timings={"total": 0.0})

    return solve_iter


def gated_run(qtbot, window, monkeypatch) -> tuple[threading.Event, list]:
    """A method running on the demo pair, :func:`fake_solver` in place of the methods, waiting until the returned
    event is set; the list returned collects the results the window reports."""
    import corrlib.methods

    gate = threading.Event()
    fake = fake_solver(4)

    def gated(*args, **kwargs):
        assert gate.wait(30)
        return (yield from fake(*args, **kwargs))

    monkeypatch.setattr(corrlib.methods, "solve_iter", gated)
    window.load_demo()
    wait_loaded(qtbot, window)
    ready = []
    window.result_ready.connect(ready.append)
    window.run_method(method="descriptor-nn")
    return gate, ready


def test_unmatched_vertices_are_left_out_of_the_error(qtbot, window, monkeypatch):
    import corrlib.methods
    from app.views.scene import UNMATCHED_GREY

    monkeypatch.setattr(corrlib.methods, "solve_iter", fake_solver(4))
    window.load_demo()
    wait_loaded(qtbot, window)
    payloads = []
    window.runner.finished.connect(lambda key, payload: payloads.append(payload))
    run_and_wait(qtbot, window, "descriptor-nn")
    outcome = payloads[-1]
    n = window.source.n_vertices
    unmatched = np.arange(n)[::4]
    assert outcome.n_unmatched == unmatched.size
    errors = outcome.errors
    assert errors.n_unmatched == unmatched.size and errors.n_rows == n
    assert errors.report.errors.size == n - unmatched.size  # only matched rows are scored
    # the matched vertices are where the identity ground truth puts them: zero error. Counting the
    # unmatched ones as matched to vertex 0 would give them large errors.
    assert errors.report.summary()["mean"] < 1e-6
    view = window.pair_view
    assert np.all(np.isnan(view.errors[unmatched]))
    assert np.all(np.isfinite(np.delete(view.errors, unmatched)))
    assert f"{unmatched.size} source vertices unmatched" in view.info.text()
    assert "mean geodesic error 0.0000" in view.info.text()
    assert f"{unmatched.size} of {n} rows unmatched" in window.job_panel.log.toPlainText()
    # neutral colour on the target where the map has no partner; texture and error modes draw too
    view.mode.setCurrentText("coordinates")
    assert np.allclose(view.target_colors[::4], UNMATCHED_GREY)
    assert not np.allclose(view.target_colors[1::4], UNMATCHED_GREY)
    for mode in ("texture", "error", "lines"):
        view.mode.setCurrentText(mode)
    assert view.lines is not None and view.lines.n_cells == sum(1 for v in view.picked if v % 4)


def test_map_errors_counts_unmatched_rows(wolf_pair):
    from app.jobs import map_errors

    _source, target = wolf_pair
    n = target.n_vertices
    map_xy = np.arange(n)
    map_xy[:10] = -1
    gt = np.arange(0, n, 2)  # ground truth on every other vertex: 5 of the first 10 rows are unmatched
    out = map_errors(map_xy, target, gt, gt)
    assert out.n_unmatched == 5 and out.n_rows == gt.size
    assert out.report.errors.size == gt.size - 5 and np.allclose(out.report.errors, 0.0, atol=1e-9)
    assert np.isnan(out.per_vertex[:10]).all() and np.isnan(out.per_vertex[1::2]).all()
    none = map_errors(np.full(n, -1), target, gt, gt)
    assert none.report is None and none.n_unmatched == gt.size


def test_map_errors_are_corr_bench_figures_and_a_pinched_target_falls_back(wolf_pair):
    """The studio's errors are the exact geodesic errors `corr bench` reports (they were the heat method's, a
    few per cent off and several times slower); where exact geodesics are ruled out (a pinched vertex) the heat
    method's figures come with a note instead of no figures."""
    from app.jobs import map_errors
    from conftest import pinched_spheres
    from corrlib.evaluation import geodesic_errors

    _source, target = wolf_pair
    n = target.n_vertices
    rng = np.random.default_rng(3)
    map_xy = np.where(rng.random(n) < 0.2, rng.integers(0, n, n), np.arange(n))
    gt = np.arange(n)
    out = map_errors(map_xy, target, gt, gt)
    assert np.array_equal(out.report.errors, geodesic_errors(map_xy, target, gt, gt).errors) and out.note == ""
    pinched, _pinch = pinched_spheres()
    m = pinched.n_vertices
    out = map_errors(np.roll(np.arange(m), 9), pinched, np.arange(m), np.arange(m))
    assert "heat method" in out.note and "pinched.off" in out.note
    assert np.all(np.isfinite(out.report.errors)) and out.report.summary()["mean"] > 0


def test_sequence_options_leave_out_a_motion_that_cannot_be_built(wolf_pair, monkeypatch):
    """The default motion's error is the job's (as before there was a choice); a further motion that fails with a
    named error is left out of the choice instead of losing the result."""
    import corrlib.morph
    from app.jobs import sequence_options
    from corrlib.errors import InputError
    from corrlib.methods.base import MatchResult

    source, target = wolf_pair
    ident = np.arange(source.n_vertices)
    result = MatchResult("descriptor-nn", ident, ident)
    assert list(sequence_options(result, source, target)) == ["rigid", "linear"]
    real = corrlib.morph.sequence_positions

    def failing(kind):
        def positions(result, source, target, t_max=1.5, interpolation="auto"):
            if corrlib.morph.sequence_kind(result, interpolation) == kind:
                raise InputError(f"no {kind} motion here")
            return real(result, source, target, t_max=t_max, interpolation=interpolation)
        return positions

    monkeypatch.setattr(corrlib.morph, "sequence_positions", failing("linear"))
    assert list(sequence_options(result, source, target)) == ["rigid"]
    monkeypatch.setattr(corrlib.morph, "sequence_positions", failing("rigid"))
    with pytest.raises(InputError, match="no rigid motion"):
        sequence_options(result, source, target)


def test_map_errors_with_mirrored_rows_and_the_heat_map_fill(wolf_pair):
    """A map onto the 'mirrored' partners has a large direct and zero mirror-accepted error; per-vertex
    errors stay direct (a flip glows in the heat map), and the display fill keeps unmatched vertices grey."""
    from app.jobs import map_errors
    from app.views.compare import spread_to_matched

    _source, target = wolf_pair
    n = target.n_vertices
    gt = np.arange(0, n, 2)
    mirrored = np.random.default_rng(0).permutation(n)[gt]  # any other partners serve as the mirrored rows
    map_xy = np.arange(n)
    map_xy[gt] = mirrored
    map_xy[1] = -1
    out = map_errors(map_xy, target, gt, gt, mirrored)
    summary = out.report.summary()
    assert summary["mean"] > 0.1 and summary["mean_sym"] == pytest.approx(0.0, abs=1e-9)
    assert np.nanmean(out.per_vertex) == pytest.approx(summary["mean"])
    shown = spread_to_matched(target.vertices, out.per_vertex, map_xy)
    assert np.isnan(shown[1]) and np.isfinite(np.delete(shown, 1)).all()
    assert np.array_equal(shown[gt], out.per_vertex[gt])


def test_bad_file_shows_a_message_and_the_window_keeps_running(qtbot, tmp_path, monkeypatch):
    import corrlib.io
    from PySide6.QtWidgets import QMessageBox

    shown = []
    monkeypatch.setattr(QMessageBox, "critical", lambda parent, title, text: shown.append(text))
    load_calls = []
    real_load_mesh = corrlib.io.load_mesh
    gate = threading.Event()

    def gated_load_mesh(path, **kwargs):
        load_calls.append(on_gui_thread())
        assert gate.wait(10), "the test never opened the gate"
        return real_load_mesh(path, **kwargs)

    monkeypatch.setattr(corrlib.io, "load_mesh", gated_load_mesh)
    win = make_window(qtbot, tmp_path / "s.ini", interactive=True)
    bad = tmp_path / "broken.off"
    bad.write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n")
    win.load_file(str(bad), "source")
    # load_file returned while the reader waits at the gate: the GUI thread is free
    assert win.is_loading() and win.source is None
    qtbot.wait(50)
    gate.set()
    qtbot.waitUntil(lambda: bool(shown), timeout=30_000)
    assert "broken.off" in shown[0] and "failed" in win.job_panel.stage.text()
    assert win.source is None  # nothing half-loaded
    wait_loaded(qtbot, win)
    # a reader failing with an exception that is no CorrError (a third-party bug): a message too
    def broken_reader(path, **_kwargs):
        raise RuntimeError("reader bug")

    monkeypatch.setattr(corrlib.io, "load_contour", broken_reader)
    win.load_file(str(tmp_path / "points.txt"), "source")
    qtbot.waitUntil(lambda: len(shown) == 2, timeout=30_000)
    assert "points.txt: cannot load: reader bug" in shown[1] and win.source is None
    # the window keeps running: the next files load, the method list follows
    win.load_file(str(TOSCA / "wolf0.off"), "source")
    win.load_file(str(TOSCA / "wolf1.off"), "target")
    wait_loaded(qtbot, win)
    assert win.source.name == "wolf0.off" and win.target.name == "wolf1.off"
    assert win.method_box.count() > 0
    assert "vertices" in win.source_info.text()  # the description (validation included) came from the job
    assert load_calls and not any(load_calls)  # every mesh was read in the worker
    win.close()


def test_a_result_for_replaced_inputs_is_dropped(qtbot, window, monkeypatch):
    gate, ready = gated_run(qtbot, window, monkeypatch)
    window.load_file(str(TOSCA / "cat0.off"), "target")
    wait_loaded(qtbot, window)  # the new target cancels the running method
    gate.set()
    qtbot.waitUntil(lambda: not window.runner.is_running("pair"), timeout=30_000)
    qtbot.wait(100)
    assert not ready and window.pair_view.result is None and window.target.name == "cat0.off"


def test_sequence_slider_range_is_the_flow_horizon(qtbot):
    from app.views.sequence import SequenceView
    from corrlib.methods.divergence_free import SEQUENCE_T_MAX

    view = keep_widget(SequenceView())
    assert view.t_max.maximum() == SEQUENCE_T_MAX
    view.close_plotters()


def test_no_long_functions_in_app():
    long = []
    for path in sorted(APP.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = node.end_lineno - node.lineno + 1
                if lines > MAX_FUNCTION_LINES:
                    long.append(f"{path.relative_to(APP.parent)}:{node.name} ({lines} lines)")
    assert not long, long


_CLOSED_WINDOWS = []


def test_a_window_lives_until_the_end_of_its_test(qtbot, window):
    _CLOSED_WINDOWS.append(window)
    assert window.isVisible()


def test_the_previous_tests_window_is_closed_and_kept(qtbot):
    """conftest's teardown hook closes a test's windows at its end (no job of theirs runs on into the next
    test) and keeps them: deleting closed VTK windows crashed the tests now and then."""
    import shiboken6

    from _studio import CLOSED_WIDGETS
    from app.gui_gc import studio_threads_alive

    previous = _CLOSED_WINDOWS[0]
    assert shiboken6.isValid(previous) and not previous.isVisible() and previous in CLOSED_WIDGETS
    assert previous._closed and not studio_threads_alive()


def test_a_failed_load_keeps_the_running_method_and_cancel_stays_for_a_job_that_goes_on(qtbot, window, monkeypatch,
                                                                                       tmp_path):
    """Found by fuzzing the studio: a load cancelled the running method when it *started*, so a file that failed to
    load lost the run for nothing; and the shared job panel turned Cancel off when one job ended while another
    still ran. Also: the status bar kept an old error after a good load."""
    gate, ready = gated_run(qtbot, window, monkeypatch)
    (tmp_path / "empty.off").write_text("")
    window.load_file(str(tmp_path / "empty.off"), "source")
    wait_loaded(qtbot, window)  # the load failed: the pair did not change
    assert "empty.off" in window.statusBar().currentMessage()
    assert window.runner.is_running("pair") and window.job_panel.cancel.isEnabled()
    assert "still running: the method" in window.job_panel.stage.text()
    gate.set()
    qtbot.waitUntil(lambda: bool(ready), timeout=30_000)  # the run finished and its result stands
    assert window.pair_view.result is not None and not window.job_panel.cancel.isEnabled()
    assert window.statusBar().currentMessage().endswith(" finished")  # not "press Run" any more
    window.load_file(str(TOSCA / "wolf0.off"), "source")
    wait_loaded(qtbot, window)
    assert window.statusBar().currentMessage() == "Pick a method and press Run."


def test_a_new_input_clears_the_last_pair_s_match_and_a_mesh_to_a_contour_is_explained(qtbot, window):
    """Found by fuzzing the studio: the Product tab kept the last pair's match after new inputs were loaded, and a
    mesh source with a contour target was told "load a source and a target" though both were loaded."""
    from corrlib.io import load_mesh

    view = window.product_view
    wolf = load_mesh(TOSCA / "wolf0.off")
    angles = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    view.show_contour_match(np.column_stack([np.cos(angles), np.sin(angles)]), wolf, np.arange(40), np.arange(40),
                            1.0)
    assert view.curve is not None
    window.load_file(str(TOSCA / "wolf0.off"), "source")
    window.load_file(str(ROOT / "resources" / "data" / "sketch2d" / "human_sketch_a_contour.txt"), "target")
    wait_loaded(qtbot, window)
    assert view.curve is None and view.mesh_points is None and view.info.text().startswith("Match a contour")
    assert window.pair_view.info.text() == \
        "The target is a contour: a 2D-to-3D match takes the contour as the source."
    shown = []
    window.error_shown.connect(shown.append)
    window.run_method()
    assert shown == ["no method to run: no method matches a mesh to a contour: a 2D-to-3D match takes the contour "
                     "as the source and the mesh as the target."]
