"""The studio under a virtual X server (pytest-xvfb, Qt's xcb platform): drive the real window."""

import os
import re
import shutil

import numpy as np
import pytest

os.environ.setdefault("QT_QPA_PLATFORM", "xcb")
pytest.importorskip("pyvistaqt")  # the gui extra is part of the test setup (scripts/test.sh installs it)

from _data import SILHOUETTES, TOSCA  # noqa: E402
from _studio import make_window, wait_loaded  # noqa: E402

FAST_KERNEL = {"n_eigs": 100, "n_seeds": 500, "n_times": 4, "iters_per_time": 2}


def load_demo(qtbot, win):
    win.load_demo()
    wait_loaded(qtbot, win)


def load_file(qtbot, win, path, which):
    """Load ``path`` and wait; True if it became the ``which`` shape."""
    win.load_file(str(path), which)
    wait_loaded(qtbot, win)
    shape = win.source if which == "source" else win.target
    return shape is not None and shape.name == os.path.basename(str(path))


def set_params(win, method, **values):
    form = win.form_of(method)
    current = form.values()
    current.update(values)
    form.set_values(current)


def run_and_wait(qtbot, win, method, timeout=180_000):
    with qtbot.waitSignal(win.result_ready, timeout=timeout) as blocker:
        win.run_method(method=method)
    return blocker.args[0]


@pytest.mark.slow
def test_demo_pair_kernel_matching_colours_the_target(qtbot, window):
    load_demo(qtbot, window)
    assert window.method_box.currentData() == "kernel-matching"  # the best method for two meshes
    set_params(window, "kernel-matching", **FAST_KERNEL)
    result = run_and_wait(qtbot, window, "kernel-matching")
    colors = window.pair_view.target_colors
    assert colors is not None and colors.shape == (window.target.n_vertices, 3)
    assert colors.std(axis=0).min() > 0.1  # not the default grey
    assert "within 0.05" in window.pair_view.info.text()  # demo ground truth is the identity
    assert result.map_xy.shape == (window.source.n_vertices,)
    for mode in ("texture", "error", "coordinates"):
        window.pair_view.mode.setCurrentText(mode)
    # the sequence slider moves the vertices in place (drawn in the source's display frame)
    seq = window.sequence_view
    seq.slider.setValue(0)
    start = np.array(seq.mesh.points)
    assert np.allclose(start, seq.display.points(window.source.vertices))
    seq.slider.setValue(600)
    moved = np.array(seq.mesh.points)
    assert np.abs(moved - start).max() > 0.01  # display units: the source's diagonal is 1
    from corrlib.morph import frame_positions

    assert "as-rigid-as-possible" in seq.kind.text()  # a map without a deformation of its own
    expected = frame_positions(result, window.source, window.target, [seq.t()])[0]
    assert np.allclose(moved, seq.display.points(expected))


@pytest.mark.slow
@pytest.mark.parametrize("method", ["fmap-zoomout", "descriptor-nn"])
def test_other_mesh_methods(qtbot, window, method):
    load_demo(qtbot, window)
    result = run_and_wait(qtbot, window, method)
    assert result.method == method and window.pair_view.target_colors is not None


def test_contour_to_mesh_draws_the_curve(qtbot, window):
    assert load_file(qtbot, window, SILHOUETTES / "mpeg7" / "dog-1.gif", "source")
    assert load_file(qtbot, window, TOSCA / "wolf1.off", "target")
    assert window.method_box.currentData() == "contour3d"
    set_params(window, "contour3d", n_contour=60, eps=0.05)
    result = run_and_wait(qtbot, window, "contour3d")
    curve = window.product_view.curve
    assert curve is not None and curve.n_points == len(result.path.vertices)
    assert window.tabs.currentWidget() is window.product_view
    # the job log says how the query was read (a dog from the side: a side view) and how to force the other view
    log = window.job_panel.log.toPlainText()
    assert f"read as a {result.extras['view']} view" in log and "view=side or view=front" in log
    assert result.extras["view"] == "side" and f"{result.extras['intrinsic_asymmetry']:.3f}" in log
    bar = window.job_panel.log.verticalScrollBar()
    assert bar.value() == bar.maximum()  # the log shows its last line
    bar.setValue(0)  # a reader who scrolled up is not moved by new lines
    window.job_panel.write("one more line")
    assert bar.value() == 0


def test_a_drawing_matched_through_views_draws_the_curve(qtbot, window):
    from corrlib.resources import resource

    assert load_file(qtbot, window, resource("data/silhouettes/drawn/wolf.txt"), "source")
    assert load_file(qtbot, window, TOSCA / "wolf0.off", "target")
    assert [window.method_box.itemData(i) for i in range(window.method_box.count())] == ["contour3d", "contour-views"]
    result = run_and_wait(qtbot, window, "contour-views")
    curve = window.product_view.curve
    assert curve is not None and curve.n_points == len(result.path.vertices)
    assert "outline seen along" in window.job_panel.log.toPlainText()  # which view won


def test_sketch_becomes_a_query(qtbot, window):
    t = np.linspace(0, 2 * np.pi, 80, endpoint=False)
    window.sketch.area.set_points(np.column_stack([120 + 80 * np.cos(t), 100 + 50 * np.sin(3 * t) / 3 + 40 * np.sin(t)]))
    with qtbot.waitSignal(window.sketch.contour_ready, timeout=5000) as blocker:
        window.sketch.emit_contour()
    contour = blocker.args[0]
    assert contour.n_points == window.sketch.n_points.value() and contour.is_ccw
    assert window.source is contour and window.retrieval_view.query is contour
    assert "crossed itself" not in window.sketch.status.text() and len(window.sketch.area.strokes) == 1


def test_a_stroke_that_crosses_itself_is_read_as_the_region_it_encloses(qtbot, window):
    from corrlib.shapes import inspect_contour

    t = np.linspace(0, 2 * np.pi, 80, endpoint=False)
    on = np.linspace(0.05, 0.3, 6)  # the hand goes on past the start, then in across the stroke
    stroke = np.vstack([np.column_stack([120 + 80 * np.cos(t), 100 + 60 * np.sin(t)]),
                        np.column_stack([120 + 82 * np.cos(on), 100 + 62 * np.sin(on)]),
                        [[120 + 72 * np.cos(0.3), 100 + 54 * np.sin(0.3)]]])
    assert [f.code for f in inspect_contour(stroke)] == ["self-intersection"]
    window.sketch.area.set_points(stroke)
    with qtbot.waitSignal(window.sketch.contour_ready, timeout=5000) as blocker:
        window.sketch.emit_contour()
    assert blocker.args[0].area == pytest.approx(np.pi * 80 * 60, rel=0.02)
    assert "crossed itself" in window.sketch.status.text()
    assert not inspect_contour(window.sketch.area.points())  # the canvas shows the outline used
    window.sketch.area.undo()
    np.testing.assert_array_equal(window.sketch.area.points(), stroke)


@pytest.mark.slow
def test_retrieval_gallery_order(qtbot, window, tmp_path):
    from corrlib.geometry.sections import render_silhouette
    from corrlib.io import load_mesh

    folder = tmp_path / "collection"
    folder.mkdir()
    for name in ("wolf0.off", "wolf1.off", "cat0.off"):
        shutil.copy(TOSCA / name, folder / name)
    (folder / "empty.off").write_text("")  # not ranked, and the log says why (it said only "inf")
    wolf = load_mesh(TOSCA / "wolf0.off")
    axes = np.linalg.svd(wolf.vertices - wolf.vertices.mean(0), full_matrices=False)[2]
    window.retrieval_view.set_query(render_silhouette(wolf, axes[2], 300, up=axes[1]))
    window.retrieval_view.set_folder(str(folder))
    with qtbot.waitSignal(window.result_ready, timeout=180_000):
        window.run_retrieval()
    names = window.retrieval_view.ranked_names()
    assert len(names) == 4 and set(names[:2]) == {"wolf0.off", "wolf1.off"} and names[3] == "empty.off"
    assert window.job_panel.stage.text() == "ranked 3 meshes; 1 could not be matched (see the log)"
    assert "not ranked: empty.off: " in window.job_panel.log.toPlainText()
    gallery = window.retrieval_view.gallery
    qtbot.waitUntil(lambda: window.retrieval_view.thumbnails_pending() == 0, timeout=30_000)
    assert not any(gallery.item(i).icon().isNull() for i in range(4))  # empty.off: a "not matched" picture
    assert gallery.item(3).text().endswith("not matched")
    assert window.retrieval_view.ranking.currentText() == "fused"
    assert all(np.isfinite(hit.view_distance) for hit in window.retrieval_view.hits if not hit.error)
    # the thesis' ranking, chosen in the tab: by energy, no views rendered
    window.retrieval_view.ranking.setCurrentText("energy")
    with qtbot.waitSignal(window.result_ready, timeout=180_000):
        window.run_retrieval()
    hits = [hit for hit in window.retrieval_view.hits if not hit.error]
    assert [h.energy for h in hits] == sorted(h.energy for h in hits) and all(np.isnan(h.view_distance) for h in hits)
    # a ranking that fails (an empty folder) leaves no gallery of the last folder standing for it
    empty = tmp_path / "empty"
    empty.mkdir()
    window.retrieval_view.set_folder(str(empty))
    messages = []
    window.error_shown.connect(messages.append)
    window.run_retrieval()
    qtbot.waitUntil(lambda: not window.runner.is_running("retrieval"), timeout=30_000)
    assert messages and window.retrieval_view.ranked_names() == []
    bar = window.job_panel.bar  # a failed job does not leave the bar at 100 %
    assert bar.value() == 0 and bar.text() == "failed"


@pytest.mark.slow
def test_compare_two_methods(qtbot, window):
    load_demo(qtbot, window)
    view = window.compare_view
    for i in range(view.methods.count()):
        name = view.methods.item(i).data(0x0100)
        view.methods.item(i).setCheckState(
            view.methods.item(i).checkState().Checked if name in ("descriptor-nn", "fmap-zoomout")
            else view.methods.item(i).checkState().Unchecked)
    with qtbot.waitSignal(window.result_ready, timeout=180_000):
        window.run_compare()
    qtbot.waitUntil(lambda: not window.runner.is_running("compare"), timeout=180_000)
    rows = view.table_rows()
    assert [r[0] for r in rows] == ["fmap-zoomout", "descriptor-nn"]
    assert all(float(r[2]) >= 0 for r in rows)  # mean errors from the demo ground truth
    # the share of the target's area each map reaches (trimesh's vertex areas: a third of each face's)
    import trimesh

    target = window.target
    vertex_areas = trimesh.Trimesh(target.vertices, target.faces, process=False).area_faces.repeat(3) / 3
    vertex_areas = np.bincount(target.faces.ravel(), vertex_areas, minlength=target.n_vertices)
    results = {row["method"]: row["result"] for row in view.rows}
    for r in rows:
        reach = vertex_areas[np.unique(results[r[0]].map_xy)].sum() / vertex_areas.sum()
        assert float(r[6]) == pytest.approx(reach, abs=1e-3) and 0 < reach <= 1
    assert len(view.figure.axes[0].lines) == 2
    # a second comparison replaces the grid; the closed one is hidden and kept, never deleted while the studio runs
    import shiboken6

    first = view.plotter.interactor
    with qtbot.waitSignal(window.result_ready, timeout=180_000):
        window.run_compare()
    qtbot.waitUntil(lambda: not window.runner.is_running("compare"), timeout=180_000)
    qtbot.wait(50)
    assert view.plotter.interactor is not first and view.plotter.interactor.isVisible()
    assert shiboken6.isValid(first) and not first.isVisible() and view.views_box.indexOf(first) == -1


def test_compare_shows_mirror_accepted_errors_heat_maps_and_sorts(qtbot, window):
    """The cats' ground truth brings its mirrored rows (cat1.sym.vts next to cat1.vts): the table gives the
    mirror-accepted error next to the direct one, the views switch to error heat maps, a click sorts."""
    from PySide6.QtCore import Qt

    assert load_file(qtbot, window, TOSCA / "cat0.off", "source")
    assert load_file(qtbot, window, TOSCA / "cat1.off", "target")
    window.load_ground_truth(str(TOSCA / "cat0.vts"), str(TOSCA / "cat1.vts"))
    assert window.gt[2] is not None and window.gt[2].shape == window.gt[1].shape
    view = window.compare_view
    for i in range(view.methods.count()):
        item = view.methods.item(i)
        item.setCheckState(Qt.Checked if item.data(Qt.UserRole) in ("descriptor-nn", "fmap-zoomout")
                           else Qt.Unchecked)
    with qtbot.waitSignal(window.result_ready, timeout=180_000):
        window.run_compare()
    qtbot.waitUntil(lambda: not window.runner.is_running("compare"), timeout=180_000)
    header = [view.table.horizontalHeaderItem(c).text() for c in range(view.table.columnCount())]
    rows = {r[0]: dict(zip(header, r)) for r in view.table_rows()}
    # the methods' objectives do not compare with each other: no column to sort them by, each in its tooltip
    tips = {view.table.item(r, 0).text(): view.table.item(r, 0).toolTip() for r in range(view.table.rowCount())}
    assert "energy" not in header and re.fullmatch(r"descriptor-nn: mean descriptor distance [\d.]+",
                                                          tips["descriptor-nn"])
    for row in rows.values():  # accepting the mirrored partner can only lower the error
        assert 0 <= float(row["mean sym"]) <= float(row["mean"])
    # nearest descriptors confuse left and right on a third of the cat, the baseline does not
    assert float(rows["descriptor-nn"]["mean sym"]) < 0.7 * float(rows["descriptor-nn"]["mean"])
    assert float(rows["fmap-zoomout"]["mean"]) < 0.05
    assert all(r["per_vertex"] is not None and np.isfinite(r["per_vertex"]).any() for r in view.rows)
    view.color_mode.setCurrentText("error heat map")
    heat_views = [r for r in view.plotter.renderers if r.actors]
    assert len(heat_views) == 3  # the source and one heat map per method
    view.table.sortByColumn(header.index("mean"), Qt.AscendingOrder)
    assert [r[0] for r in view.table_rows()] == ["fmap-zoomout", "descriptor-nn"]
    view.table.sortByColumn(header.index("mean"), Qt.DescendingOrder)
    assert [r[0] for r in view.table_rows()] == ["descriptor-nn", "fmap-zoomout"]


def test_ground_truth_beside_the_meshes_is_loaded_with_them(qtbot, window, tmp_path):
    """Meshes opened from a folder in the layout corr bench reads (<name>.vts beside each, <target>.sym.vts)
    bring their ground truth; without it, or with a file of the wrong size, there is none, and the log says
    why without a dialog."""
    assert load_file(qtbot, window, TOSCA / "cat0.off", "source")
    assert window.gt is None  # one mesh is no pair
    assert load_file(qtbot, window, TOSCA / "cat1.off", "target")
    assert window.gt is not None and window.gt[0].shape == window.gt[1].shape == window.gt[2].shape
    assert "cat0.vts, cat1.vts" in window.job_panel.log.toPlainText()
    for name in ("cat0.off", "cat1.off"):
        shutil.copy(TOSCA / name, tmp_path / name)
    assert load_file(qtbot, window, tmp_path / "cat1.off", "target")
    assert window.gt is None  # the copy has no ground truth beside it
    (tmp_path / "cat0.vts").write_text("1\n2\n3\n")
    (tmp_path / "cat1.vts").write_text("1\n2\n")
    assert load_file(qtbot, window, tmp_path / "cat0.off", "source")
    assert window.gt is None and "ground truth beside the meshes not used" in window.job_panel.log.toPlainText()
    # the same pair through the File menu: a named error, no ground truth
    with qtbot.waitSignal(window.error_shown, timeout=5000) as blocker:
        window.load_ground_truth(str(tmp_path / "cat0.vts"), str(tmp_path / "cat1.vts"))
    assert "3 rows" in blocker.args[0] and "correspond one to one" in blocker.args[0] and window.gt is None


def test_a_mesh_with_loose_parts_is_repaired_into_a_new_file_and_opened(qtbot, window, tmp_path):
    """The loader refuses a mesh with a loose part and says where the studio repairs it; the repair writes the
    mesh and its input vertices beside it, opens it, and the Shapes dock says what was repaired."""
    from corrlib.io import load_mesh, save_mesh

    wolf = load_mesh(TOSCA / "wolf0.off")
    tetrahedron = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float) * 5 + wolf.vertices.max(axis=0) + 50
    n = wolf.n_vertices
    save_mesh(tmp_path / "scan.ply", np.vstack([wolf.vertices, tetrahedron]),
              np.vstack([wolf.faces, [[n, n + 2, n + 1], [n, n + 1, n + 3], [n, n + 3, n + 2], [n + 1, n + 2, n + 3]]]))
    with qtbot.waitSignal(window.error_shown, timeout=30_000) as blocker:
        window.load_file(str(tmp_path / "scan.ply"), "source")
    assert "2 connected components" in blocker.args[0] and "File ▸ Repair and open a mesh…" in blocker.args[0]
    wait_loaded(qtbot, window)
    assert window.source is None
    window.repair_and_load(str(tmp_path / "scan.ply"), str(tmp_path / "scan.repaired.off"), "source")
    wait_loaded(qtbot, window)
    assert window.source is not None and window.source.n_vertices == n
    assert "repaired from scan.ply: kept the largest of 2 connected components" in window.source_info.text()
    index = np.loadtxt(tmp_path / "scan.repaired.source_vertices.txt", dtype=int)
    assert np.array_equal(index, np.arange(n))
    # a repair that cannot be done is an error, and the window goes on
    with qtbot.waitSignal(window.error_shown, timeout=30_000) as blocker:
        window.repair_and_load(str(tmp_path / "scan.ply"), str(tmp_path / "scan.stl"), "target")
    assert "scan.stl: the repaired mesh must name a mesh file" in blocker.args[0]
    wait_loaded(qtbot, window)
    assert window.target is None and window.source.n_vertices == n


def test_cancel_during_a_run(qtbot, window):
    load_demo(qtbot, window)
    set_params(window, "kernel-matching", n_eigs=500, n_seeds=3000)
    with qtbot.waitSignal(window.runner.progress, timeout=60_000):
        window.run_method(method="kernel-matching")
    with qtbot.waitSignal(window.runner.cancelled, timeout=120_000):
        window.cancel_jobs()
    assert "cancelled" in window.job_panel.stage.text()
    assert not window.runner.is_running("pair")


def test_close_during_a_run(qtbot, tmp_path):
    win = make_window(qtbot, tmp_path / "s.ini")
    settings = win.settings
    load_demo(qtbot, win)
    with qtbot.waitSignal(win.runner.progress, timeout=60_000):
        win.run_method(method="kernel-matching")
    win.close()  # cancels, waits for the worker, closes every plotter
    assert not win.runner.is_running("pair")
    assert settings.value("window/state") is not None


def test_reference_cycles_are_collected_on_the_gui_thread(qtbot, tmp_path):
    """Cycles made in a worker thread are freed by the GUI thread's collector while a window is open
    (a Qt/VTK object destroyed on a worker thread crashes the process); closing restores automatic GC."""
    import gc
    import threading

    freed_on: list[str] = []

    class Node:
        def __init__(self):
            self.me = self

        def __del__(self):
            freed_on.append(threading.current_thread().name)

    win = make_window(qtbot, tmp_path / "s.ini")
    assert not gc.isenabled()

    def make_cycles():
        for _ in range(3 * gc.get_threshold()[0]):
            Node()
            [[] for _ in range(4)]  # allocations that would trigger a generation-0 collection here

    worker = threading.Thread(target=make_cycles, name="worker")
    worker.start()
    worker.join()
    qtbot.waitUntil(lambda: len(freed_on) >= 3 * gc.get_threshold()[0], timeout=10_000)
    assert set(freed_on) == {threading.main_thread().name}
    win.close()
    assert gc.isenabled()


def test_automatic_collection_waits_for_the_studio_threads(qtbot, tmp_path):
    """A studio thread still running when the last window closes would collect the closed window's
    Qt/VTK objects once automatic collection is back: it stays off (collected on the GUI thread's
    timer) until no such thread is left."""
    import gc
    import threading

    from app.gui_gc import STUDIO_THREAD_PREFIX

    win = make_window(qtbot, tmp_path / "s.ini")
    release = threading.Event()
    straggler = threading.Thread(target=release.wait, name=f"{STUDIO_THREAD_PREFIX}test-straggler", daemon=True)
    straggler.start()
    win.close()
    qtbot.wait(1200)  # two ticks of the collector's timer
    assert not gc.isenabled()
    release.set()
    straggler.join()
    qtbot.waitUntil(gc.isenabled, timeout=5_000)


def test_the_window_fits_a_laptop_screen(qtbot, tmp_path):
    """Every dock scrolls instead of imposing its content's height, so the window's minimum size is below
    1280 x 720; at that size every dock stays on screen and the central views keep most of the width."""
    from PySide6.QtWidgets import QDockWidget

    win = make_window(qtbot, tmp_path / "s.ini")
    hint = win.minimumSizeHint()
    assert hint.width() <= 1280 and hint.height() <= 720, hint
    win.resize(1280, 720)
    qtbot.waitUntil(lambda: win.width() <= 1282 and win.height() <= 720)
    for dock in win.findChildren(QDockWidget):
        box = dock.geometry()
        assert box.right() <= win.width() and box.bottom() <= win.height(), (dock.windowTitle(), box)
    assert win.centralWidget().width() >= 0.35 * win.width()
    win.close()


def test_a_long_result_line_does_not_widen_the_window(qtbot, tmp_path):
    """A partial match's result line ("…; 490 source vertices unmatched (grey, left out of the error)") made the
    pair view's minimum width exceed a 1280-pixel screen; the line wraps."""
    from types import SimpleNamespace

    import numpy as np

    win = make_window(qtbot, tmp_path / "s.ini")
    win.resize(1280, 720)
    win.show()
    map_xy = np.arange(4344)
    map_xy[:490] = -1
    errors = np.full(4344, 0.001)
    errors[:600] = np.nan  # the unmatched, and 110 matched vertices without ground truth
    result = SimpleNamespace(method="kernel-matching", timings={"total": 6.75}, map_xy=map_xy)
    win.pair_view.set_result(result, errors, n_unmatched=490)
    qtbot.wait(200)
    text = win.pair_view.info.text()
    assert "490 source vertices unmatched" in text and "110 vertices without ground truth" in text
    assert win.minimumSizeHint().width() <= 1280 and win.width() <= 1282, (win.minimumSizeHint(), win.width())
    win.close()


def test_try_retrieval_opens_the_bundled_collection(qtbot, window, tmp_path):
    """File > Try retrieval: the Retrieval tab with 10 bundled meshes of 4 classes and a drawn person as the query; the
    collection is made of links into the bundled resources (made again when a link has gone)."""
    from corrlib.io import load_mesh
    from corrlib.resources import retrieval_collection
    from corrlib.retrieval import class_of, mesh_files

    window.try_retrieval()
    view = window.retrieval_view
    assert window.tabs.currentWidget() is view
    assert view.query is not None and view.query.name == "human_sketch_a_contour.txt"
    files = mesh_files(view.folder)
    assert len(files) == 10 and sorted({class_of(f) for f in files}) == ["cat", "human", "lion", "wolf"]
    people = [load_mesh(f) for f in files if class_of(f) == "human"]
    assert len({p.n_vertices for p in people}) == 1 and not np.allclose(people[0].vertices, people[3].vertices)
    # a collection elsewhere, one of whose links broke: it is repaired, not copied onto the broken link
    folder = retrieval_collection(tmp_path / "collection")
    (folder / "lion0.off").unlink()
    (folder / "lion0.off").symlink_to(tmp_path / "gone.off")
    retrieval_collection(folder)
    assert load_mesh(folder / "lion0.off").n_vertices == 5000 and not (tmp_path / "gone.off").exists()


def test_bad_file_shows_a_dialog(qtbot, tmp_path, monkeypatch):
    from PySide6.QtWidgets import QMessageBox

    shown = []
    monkeypatch.setattr(QMessageBox, "critical", lambda parent, title, text: shown.append(text))
    win = make_window(qtbot, tmp_path / "s.ini", interactive=True, show=False)
    bad = tmp_path / "broken.off"
    bad.write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n")
    assert not load_file(qtbot, win, bad, "source")
    assert shown and "broken.off" in shown[0]
    assert win.source is None  # nothing half-loaded, the window keeps running
    # the hostile files of the command line's tests (test_hostile.py) through the studio's loaders
    (tmp_path / "garbage.off").write_bytes(np.random.default_rng(0).bytes(300))
    (tmp_path / "huge.off").write_text("OFF\n4 4 0\n0 0 0\n1e308 0 0\n0 1e308 0\n0 0 1e308\n3 0 2 1\n3 0 1 3\n"
                                       "3 0 3 2\n3 1 2 3\n")
    (tmp_path / "noise.png").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(40))
    circle = np.column_stack([np.cos(np.linspace(0, 6.2, 40)), np.sin(np.linspace(0, 6.2, 40))])
    np.savetxt(tmp_path / "tiny.txt", circle * 1e-300)
    (tmp_path / "empty.svg").write_text("<svg>")
    for name in ("garbage.off", "huge.off", "noise.png", "tiny.txt", "empty.svg"):
        shown.clear()
        assert not load_file(qtbot, win, tmp_path / name, "source")
        assert shown and name in shown[0], (name, shown)
        assert win.source is None
    assert load_file(qtbot, win, TOSCA / "wolf0.off", "source")
    win.close()


def test_a_parameter_the_form_cannot_hold_is_said_not_clamped(qtbot, window):
    """--param values outside a parameter's range, unknown choices and non-boolean words were clamped or
    dropped by the widgets without a word; a small value inside the range (σ² = 1e-6) was rounded to 0 by a
    4-decimal spin box and then refused as a value the user never typed."""
    from app.main import apply_param

    load_demo(qtbot, window)
    for item, message in [("n_eigs=99999", "above its maximum"), ("descriptor=bogus", "is not one of"),
                          ("reorient=maybe", "cannot interpret 'maybe'")]:
        error = apply_param(window, item, "kernel-matching")
        assert error is not None and message in error, (item, error)
    assert apply_param(window, "sigma2=1e-6", "divergence-free") is None
    assert window.form_of("divergence-free").values()["sigma2"] == pytest.approx(1e-6)
    assert "tau_min (0.000518) must not exceed tau_max (0.0001)" in apply_param(window, "tau_max=0.0001",
                                                                              "kernel-matching")
    window.form_of("divergence-free").reset()
    window.form_of("kernel-matching").reset()


def test_invalid_parameters_are_flagged(qtbot, window):
    load_demo(qtbot, window)
    form = window.form_of("kernel-matching")
    form.widgets["times"].setText("0.1, abc")
    assert not form.validate() and "times" in form.error.text()
    messages = []
    window.error_shown.connect(messages.append)
    window.run_method(method="kernel-matching")
    assert messages and "invalid parameters" in messages[0]
    assert not window.runner.is_running("pair")
    form.reset()
    assert form.validate() and form.error.text() == ""


@pytest.mark.slow
def test_exports_are_written(qtbot, window, tmp_path, monkeypatch):
    from corrlib.io import load_map, load_mesh

    load_demo(qtbot, window)
    run_and_wait(qtbot, window, "descriptor-nn")
    targets = iter([str(tmp_path / "map.txt"), str(tmp_path / "colored.ply"), str(tmp_path / "shot.png")])
    monkeypatch.setattr(window, "_save_path", lambda *a: next(targets))
    window.export_map("txt")
    window.export_colored()
    window.export_screenshot()
    assert load_map(tmp_path / "map.txt").shape == (window.source.n_vertices,)
    assert load_mesh(tmp_path / "colored.ply").n_vertices == window.target.n_vertices
    assert (tmp_path / "shot.png").read_bytes()[:4] == b"\x89PNG"


@pytest.mark.slow
def test_lines_function_texture_and_sequence_exports(qtbot, window, tmp_path, monkeypatch):
    from PIL import Image

    from corrlib.io import load_mesh

    load_demo(qtbot, window)
    result = run_and_wait(qtbot, window, "descriptor-nn")
    from corrlib.morph import folded_share, frame_positions

    at_one = frame_positions(result, window.source, window.target, [1.0])[0]  # the default motion's last frame
    share = folded_share(at_one, window.source.faces, window.target, result.map_xy)
    assert share > 0 and (f"descriptor-nn: last frame (t = 1, on wolf1.off's surface): {100 * share:.1f} % of the "
                          "faces turned over where the map crosses itself") in window.job_panel.log.toPlainText()
    view = window.pair_view
    view.mode.setCurrentText("lines")
    assert view.lines is not None and view.lines.n_cells == len(view.picked) == 12
    view.add_line(100)  # what a mouse pick on the source does
    assert view.lines.n_cells == 13
    # the line from vertex 100 ends at its partner (shifted with the target)
    view.mode.setCurrentText("function")
    assert view.target_colors is not None and view.target_colors.std() > 0.05
    img = np.zeros((32, 32, 3), np.uint8)
    img[:, :16] = 255
    Image.fromarray(img).save(tmp_path / "tex.png")
    window.load_texture(str(tmp_path / "tex.png"))
    assert view.mode.currentText() == "texture" and view.texture_image.shape == (32, 32, 3)
    paths = window.export_frames(".ply", folder=str(tmp_path))
    assert len(paths) == 12  # 11 evenly spaced to t max 1.5, and t = 1 (the target)
    last = load_mesh(paths[-1])
    t_max = window.sequence_view.t_max.value()
    expected = frame_positions(result, window.source, window.target, [t_max])[0]  # extrapolated beyond the target
    assert np.allclose(last.vertices, expected, atol=1e-4)
    # the other motion through the map: shown at the same t, and what the export then writes
    seq = window.sequence_view
    assert [seq.motion.itemData(i) for i in range(seq.motion.count())] == ["rigid", "linear"]
    seq.slider.setValue(400)
    seq.motion.setCurrentIndex(1)
    assert seq.slider.value() == 400 and "linear" in seq.kind.text()
    linear = frame_positions(result, window.source, window.target, [seq.t(), t_max], interpolation="linear")
    assert np.allclose(seq.mesh.points, seq.display.points(linear[0]))
    last = load_mesh(window.export_frames(".ply", folder=str(tmp_path / "linear"))[-1])
    assert np.allclose(last.vertices, linear[1], atol=1e-4) and not np.allclose(last.vertices, expected, atol=1e-3)
    at_one = frame_positions(result, window.source, window.target, [1.0], interpolation="linear")[0]
    share = folded_share(at_one, window.source.faces, window.target, result.map_xy)
    assert f"; last frame (t = 1, on wolf1.off's surface): {100 * share:.1f} % of the faces turned over" in \
        window.job_panel.log.toPlainText()
    monkeypatch.setattr(window, "_save_path", lambda *a: str(tmp_path / "strip.png"))
    window.export_strip()
    strip = np.asarray(Image.open(tmp_path / "strip.png"))
    assert strip.shape[1] >= 6 * 100 and strip.shape[1] > 3 * strip.shape[0]


def test_bundled_shapes_and_retrieved_pair(qtbot, window):
    labels = [window.bundled.itemText(i) for i in range(window.bundled.count())]
    assert "tosca/cat0.off" in labels and "silhouettes/mpeg7/dog-1.gif" in labels
    window.bundled.setCurrentIndex(labels.index("silhouettes/mpeg7/dog-1.gif"))
    window.load_bundled("source")
    wait_loaded(qtbot, window)
    assert window.source.name == "dog-1.gif"
    set_params(window, "contour3d", n_contour=40, eps=0.1)
    with qtbot.waitSignal(window.result_ready, timeout=120_000):
        window.open_retrieved_pair(window.source, str(TOSCA / "wolf0.off"))  # a double-click in the gallery
    assert window.target.name == "wolf0.off" and window.product_view.curve is not None


def test_contour_pair_shows_the_torus(qtbot, window):
    from app.views.product import TORUS_BAR, TORUS_BAR_BAND

    assert load_file(qtbot, window, SILHOUETTES / "mpeg7" / "dog-1.gif", "source")
    assert load_file(qtbot, window, SILHOUETTES / "mpeg7" / "horse-1.gif", "target")
    assert window.method_box.currentData() == "contour2d"
    # the other tabs say where the match is and that a match of contours has no motion
    from app.views.sequence import SEQUENCE_HINT

    assert window.pair_view.info.text() == "Both inputs are contours: their correspondence is shown in the Product tab."
    seq = window.sequence_view
    assert seq.kind.text() == SEQUENCE_HINT and seq.motion.isHidden() and not seq.play_button.isEnabled()
    set_params(window, "contour2d", n_source=50, n_target=50)
    result = run_and_wait(qtbot, window, "contour2d")
    view = window.product_view
    assert view.torus_curve is not None and view.torus_curve.n_points == len(result.path.layers)
    assert view.function.currentText() == "cost"
    listed = [view.function.itemText(i) for i in range(view.function.count())]
    assert {"density", "harmonic_1"} <= set(listed)  # the product-manifold refinement's functions
    view.function.setCurrentText("harmonic_1")  # redraws the torus with the localized harmonic
    assert view.function.currentText() == "harmonic_1"
    # the new function's colour bar, drawn (bars are kept by title, and all are untitled)
    bars = list(view.plotter.scalar_bars.values())
    assert len(bars) == 1 and any(r.HasViewProp(bars[0]) for r in view.plotter.renderers)
    assert bars[0].GetLookupTable().GetRange()[1] == pytest.approx(result.path.product_functions["harmonic_1"].max())
    # the flat square fills its viewport and is whole, drawn when the widget was still small and after a resize
    # (VTK's own reset cut its sides in a laptop's window)
    corners = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]])
    for size in ((1100, 700), (1500, 700)):
        window.resize(*size)
        qtbot.wait(100)
        view.plotter.render()
        width, height = view.plotter.render_window.GetSize()
        # the flat square, and the two contours side by side (their points' correspondence) above the tori
        # the square is fitted with the band of its colour bar below it
        square = np.vstack([corners, [[0.5, -TORUS_BAR_BAND, 0.0]]])
        for renderer, points in ((view.plotter.renderers[2], square),
                                 (view.plotter.renderers[0], view.contours_shown)):
            x0, y0, x1, y1 = np.array(renderer.GetViewport()) * [width, height, width, height]
            screen = []
            for point in points:
                renderer.SetWorldPoint(*point, 1.0)
                renderer.WorldToDisplay()
                screen.append(renderer.GetDisplayPoint()[:2])
            screen = np.array(screen)
            assert np.all(screen >= [x0 - 1, y0 - 1]) and np.all(screen <= [x1 + 1, y1 + 1]), (size, screen)
            assert max(np.ptp(screen[:, 0]) / (x1 - x0), np.ptp(screen[:, 1]) / (y1 - y0)) > 0.8
            if renderer is view.plotter.renderers[2]:  # the bar is under the square, not over it
                assert screen[:4, 1].min() > y0 + (TORUS_BAR["position_y"] + TORUS_BAR["height"]) * (y1 - y0)
    a, b = view.contours_shown[:50], view.contours_shown[50:]
    assert a.shape == (50, 3) and b.shape == (50, 3) and a[:, 0].max() < b[:, 0].min()  # B to the right of A
    assert np.ptp(a[:, 1]) == pytest.approx(np.ptp(b[:, 1]))  # at one height


def test_drag_and_drop_and_recent_files(qtbot, window):
    from PySide6.QtCore import QMimeData, QPoint, Qt, QUrl
    from PySide6.QtGui import QDropEvent

    mime = QMimeData()
    mime.setUrls([QUrl.fromLocalFile(str(TOSCA / "wolf0.off")), QUrl.fromLocalFile(str(TOSCA / "wolf1.off"))])
    event = QDropEvent(QPoint(10, 10), Qt.CopyAction, mime, Qt.LeftButton, Qt.NoModifier)
    window.dropEvent(event)
    wait_loaded(qtbot, window)
    assert window.source.name == "wolf0.off" and window.target.name == "wolf1.off"
    recent = window.settings.value("recent")
    assert recent[:2] == [str(TOSCA / "wolf1.off"), str(TOSCA / "wolf0.off")]
    assert [a.text() for a in window.recent_menu.actions()][:2] == recent[:2]


def test_studio_without_display_says_so():
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "DISPLAY"}
    env["QT_QPA_PLATFORM"] = "xcb"
    proc = subprocess.run([sys.executable, "-m", "app.main", "--demo"], env=env, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2 and "no display" in proc.stderr


@pytest.mark.slow
def test_screenshot_of_a_chosen_motion(tmp_path):
    """``--sequence-motion`` picks the motion a screenshot shows; one the result lacks is said, and the default
    shown."""
    import subprocess
    import sys

    shot = tmp_path / "sequence.png"
    proc = subprocess.run([sys.executable, "-m", "app.main", "--demo", "--method", "descriptor-nn", "--tab",
                           "Sequence", "--sequence-t", "0.5", "--sequence-motion", "flow", "--screenshot", str(shot),
                           "--timeout", "300"], env={**os.environ, "QT_QPA_PLATFORM": "xcb"}, capture_output=True,
                          text=True, timeout=400)
    assert proc.returncode == 0, proc.stderr
    assert "offers no flow motion (it offers: rigid, linear)" in proc.stderr
    assert shot.stat().st_size > 10_000


def test_about_and_remembered_layout(qtbot, tmp_path, monkeypatch):
    from PySide6.QtWidgets import QMessageBox

    texts = []
    monkeypatch.setattr(QMessageBox, "about", lambda parent, title, text: texts.append(text))
    first = make_window(qtbot, tmp_path / "layout.ini", show=False)
    first.show_about()
    assert "numpy" in texts[0] and "TOSCA" in texts[0]  # versions and data provenance
    from PySide6.QtWidgets import QDockWidget

    sketch_dock = next(d for d in first.findChildren(QDockWidget) if d.objectName() == "dock-Sketch")
    sketch_dock.setFloating(True)
    first.close()
    second = make_window(qtbot, tmp_path / "layout.ini", show=False)
    again = next(d for d in second.findChildren(QDockWidget) if d.objectName() == "dock-Sketch")
    assert again.isFloating()  # the dock layout came back from QSettings
    second.close()


@pytest.mark.slow
def test_divergence_free_sequence_uses_the_flow(qtbot, window, tmp_path):
    from corrlib.io import load_mesh
    from corrlib.morph import load_glb_frames

    load_demo(qtbot, window)
    set_params(window, "divergence-free", n_samples=400, n_fields=150, max_iter=5)
    result = run_and_wait(qtbot, window, "divergence-free")
    view = window.sequence_view
    assert "divergence-free flow" in view.kind.text()
    assert np.allclose(view.positions(1.0), result.extras["morphed_vertices"], atol=1e-3)
    # the interpolations through its map are offered too; the flow stays the first
    from corrlib.morph import frame_positions

    assert [view.motion.itemData(i) for i in range(view.motion.count())] == ["flow", "rigid", "linear"]
    view.slider.setValue(300)
    view.motion.setCurrentIndex(1)
    rigid = frame_positions(result, window.source, window.target, [view.t()], interpolation="rigid")[0]
    assert np.allclose(view.mesh.points, view.display.points(rigid)) and "as-rigid" in view.kind.text()
    view.motion.setCurrentIndex(0)
    view.slider.setValue(view.slider.maximum())  # t = t max extrapolates along the flow
    assert np.allclose(view.mesh.points, view.display.points(view.positions(view.t_max.value())), atol=1e-6)
    paths = window.export_frames(".obj", folder=str(tmp_path))
    assert len(paths) == 12 and (tmp_path / "animation.glb").exists()  # t = 1 added to the 11 to t max 1.5
    assert "\n7,1," in (tmp_path / "volumes.csv").read_text()  # t = 0, 0.15, …, 0.9, 1
    assert np.allclose(load_mesh(paths[0]).vertices, view.positions(0.0), atol=1e-4)
    _faces, frames, _times = load_glb_frames(tmp_path / "animation.glb")
    assert len(frames) == 12
    assert "volume change" in window.job_panel.log.toPlainText()
    assert "turned over" not in window.job_panel.log.toPlainText()  # a flow does not fold


def test_a_new_shape_forgets_the_last_motion_and_a_bad_export_path_is_said(qtbot, window, tmp_path):
    """After a match, loading another source kept the last pair's motion: exporting frames then wrote the old
    vertices with the new faces. And a picture strip or screenshot to a path under a file raised instead of
    saying so."""
    load_demo(qtbot, window)
    run_and_wait(qtbot, window, "descriptor-nn")
    assert window.sequence_view.positions is not None
    messages = []
    window.error_shown.connect(messages.append)
    blocker = tmp_path / "afile"
    blocker.write_text("x")
    window._save_path = lambda *_args: str(blocker / "strip.png")
    window.export_strip()
    window.export_screenshot()
    assert len(messages) == 2 and all("afile" in m for m in messages), messages
    assert load_file(qtbot, window, TOSCA / "cat0.off", "source")
    assert window.sequence_view.positions is None
    assert window.sequence_view.motion.count() == 0 and not window.sequence_view.motion.isEnabled()
    assert window.export_frames(".obj", folder=str(tmp_path / "frames")) == []
    assert "no sequence to export" in messages[-1] and not (tmp_path / "frames").exists()


def test_loading_a_shape_while_a_method_runs_stops_the_method(qtbot, window, tmp_path):
    """Loading a file while a method ran took over the job panel (Cancel disabled, "failed" for a bad file)
    while the method went on: the pair is changing, so the method is stopped when the load starts."""
    load_demo(qtbot, window)
    window.run_method(method="kernel-matching")
    qtbot.waitUntil(lambda: window.runner.is_running("pair"), timeout=10_000)
    garbage = tmp_path / "garbage.off"
    garbage.write_text("not a mesh\n")
    window.load_file(str(garbage), "target")
    wait_loaded(qtbot, window)
    qtbot.waitUntil(lambda: not window.runner.is_running("pair"), timeout=30_000)
    assert window.target is not None and window.target.name == "wolf1.off"  # the bad file changed nothing


def test_a_method_that_cannot_run_leaves_the_rest_of_the_comparison(qtbot, window):
    """One method of a comparison with invalid parameters (or failing) stopped the whole queue, and its
    message did not say which method it was."""
    load_demo(qtbot, window)
    view = window.compare_view
    chosen = ("kernel-matching", "descriptor-nn")
    for i in range(view.methods.count()):
        item = view.methods.item(i)
        item.setCheckState(item.checkState().Checked if item.data(0x0100) in chosen else item.checkState().Unchecked)
    window.form_of("kernel-matching").widgets["times"].setText("0.1, abc")
    messages = []
    window.error_shown.connect(messages.append)
    window.run_compare()
    qtbot.waitUntil(lambda: not window.runner.is_running("compare"), timeout=120_000)
    assert any(m.startswith("kernel-matching: invalid parameters") for m in messages), messages
    assert [r[0] for r in view.table_rows()] == ["descriptor-nn"]
    window.form_of("kernel-matching").reset()


def test_a_matched_curve_without_length_is_drawn_as_points(qtbot, window):
    """A curve whose every step is on one vertex has no tube to draw (pyvista refused the empty mesh and the
    studio's result never showed); its vertices are drawn instead."""
    from corrlib.io import load_mesh

    wolf = load_mesh(TOSCA / "wolf0.off")
    t = np.linspace(0, 2 * np.pi, 30, endpoint=False)
    contour = np.column_stack([np.cos(t), np.sin(t)])
    view = window.product_view
    view.show_contour_match(contour, wolf, np.zeros(30, dtype=int), np.arange(30), 1.0)
    assert "30 contour points matched" in view.info.text()


def test_a_screenshot_run_whose_input_fails_says_so_and_exits_nonzero(tmp_path):
    """Found by a review: a missing input was written to the window's log only and the screenshot run exited 0,
    so a script could not tell. The error goes to stderr and the exit status is 1; the picture is still written."""
    import subprocess
    import sys

    shot = tmp_path / "shot.png"
    proc = subprocess.run([sys.executable, "-m", "app.main", str(tmp_path / "missing.off"), str(TOSCA / "wolf0.off"),
                           "--screenshot", str(shot), "--timeout", "120"], env={**os.environ, "QT_QPA_PLATFORM": "xcb"},
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1, proc.stderr
    assert "missing.off" in proc.stderr and shot.stat().st_size > 10_000


def test_a_screenshot_run_whose_job_is_refused_does_not_wait_for_it(tmp_path):
    """Found by a review: a comparison of two outlines is refused at once, but the screenshot run waited for a
    result until its --timeout. It shoots and exits 1 at once; an unknown torus function is named, not ignored."""
    import subprocess
    import sys
    import time

    horse, deer = SILHOUETTES / "mpeg7" / "horse-1.gif", SILHOUETTES / "mpeg7" / "deer-1.gif"
    env = {**os.environ, "QT_QPA_PLATFORM": "xcb"}
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "app.main", str(horse), str(deer), "--compare", "--screenshot",
                           str(tmp_path / "c.png"), "--timeout", "100"], env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 1 and "needs a source and a target mesh" in proc.stderr, proc.stderr
    assert time.perf_counter() - start < 60 and "no result within" not in proc.stderr
    proc = subprocess.run([sys.executable, "-m", "app.main", str(horse), str(deer), "--method", "contour2d",
                           "--param", "n_source=40", "--param", "n_target=40", "--torus-function", "bogus",
                           "--screenshot", str(tmp_path / "t.png"), "--timeout", "100"], env=env, capture_output=True,
                          text=True, timeout=300)
    assert "no torus function bogus (it offers: cost, " in proc.stderr, proc.stderr


def test_a_contour_loaded_as_the_target_is_not_taken_for_the_query(qtbot, window):
    """Found by a review: loading two silhouettes put the second, the target, in the sketch panel and made it
    the retrieval query, and the panel called a loaded file "drawn points". The source is the query."""
    horse, deer = SILHOUETTES / "mpeg7" / "horse-1.gif", SILHOUETTES / "mpeg7" / "deer-1.gif"
    assert load_file(qtbot, window, horse, "source")
    query = window.retrieval_view.query
    assert query is window.source and "horse-1.gif" in window.sketch.status.text()
    assert "loaded as the query" in window.sketch.status.text()
    shown = window.sketch.area.points().copy()
    assert load_file(qtbot, window, deer, "target")
    assert window.retrieval_view.query is query
    np.testing.assert_array_equal(window.sketch.area.points(), shown)
