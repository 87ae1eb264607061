"""The studio's framing and inspection: up axis, camera presets and files, point inspection across the compare
views, hover, shortcuts, picture exports and VTK thumbnails (real window under Xvfb)."""

import os
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("QT_QPA_PLATFORM", "xcb")
pytest.importorskip("pyvistaqt")

from _data import ROOT, TOSCA  # noqa: E402
from _studio import keep_widget, wait_loaded  # noqa: E402

from app.views.camera import HOVER_INTERVAL  # noqa: E402


def load_demo(qtbot, win):
    win.load_demo()
    wait_loaded(qtbot, win)


def compare(qtbot, win, methods):
    from PySide6.QtCore import Qt

    view = win.compare_view
    for i in range(view.methods.count()):
        item = view.methods.item(i)
        item.setCheckState(Qt.Checked if item.data(Qt.UserRole) in methods else Qt.Unchecked)
    with qtbot.waitSignal(win.result_ready, timeout=180_000):
        win.run_compare()
    qtbot.waitUntil(lambda: not win.runner.is_running("compare"), timeout=180_000)
    return view


def mouse_event(widget, kind, x, y):
    """A real Qt mouse event on a 3D view's widget (VTK's interactor turns it into its own event)."""
    from PySide6.QtCore import QPointF, Qt
    from PySide6.QtGui import QMouseEvent
    from PySide6.QtWidgets import QApplication

    types = {"move": QMouseEvent.MouseMove, "press": QMouseEvent.MouseButtonPress,
             "release": QMouseEvent.MouseButtonRelease}
    button = Qt.NoButton if kind == "move" else Qt.LeftButton
    buttons = Qt.LeftButton if kind == "press" else Qt.NoButton
    pos = QPointF(x, y)
    QApplication.sendEvent(widget, QMouseEvent(types[kind], pos, widget.mapToGlobal(pos), button, buttons,
                                               Qt.NoModifier))


def camera_direction(camera):
    d = np.subtract(camera.position, camera.focal_point)
    return d / np.linalg.norm(d)


def test_up_axis_and_camera_presets(qtbot, window):
    """TOSCA stands on -z: auto puts +z up in the display frame (+y); the presets look from +z (front),
    +x (side) and +y (top) of the display frame; an override re-frames every view."""
    with qtbot.waitSignal(window.result_ready, timeout=180_000):
        load_demo(qtbot, window)
        window.run_method(method="descriptor-nn")
    view = window.pair_view
    window.tabs.setCurrentWidget(view)
    source_display = view.displayed.displays[0]
    assert np.allclose(source_display.rotation[1], [0, 0, 1])  # the wolf's up is the file's +z
    points = source_display.points(window.source.vertices)
    assert np.linalg.norm(np.ptp(points, axis=0)) == pytest.approx(1.0)  # unit diagonal
    for preset, direction, up in (("front", [0, 0, 1], [0, 1, 0]), ("side", [1, 0, 0], [0, 1, 0]),
                                  ("top", [0, 1, 0], [0, 0, -1])):
        window.show_view(preset)
        camera = view.camera()
        assert np.allclose(camera_direction(camera), direction, atol=1e-9), preset
        assert np.allclose(camera.view_up, up, atol=1e-9)
    # every mode draws both shapes in their display frames (nothing in file units, off the camera)
    from app.views.pair import MODES

    framed = view.displayed
    for mode in MODES:
        view.mode.setCurrentText(mode)
        assert view.displayed is framed  # the display frames are computed once per pair and up axis
        drawn = [actor.GetBounds() for r in view.plotter.renderers for actor in r.actors.values()
                 if hasattr(actor, "GetMapper") and actor.GetMapper() is not None and actor.GetMapper().GetInput()
                 is not None and actor.GetMapper().GetInput().GetNumberOfPoints() > 100]
        assert len(drawn) >= 2, mode
        assert all(max(abs(b) for b in bounds) < 2.0 for bounds in drawn), mode
        widths = [r.GetViewport()[2] - r.GetViewport()[0] for r in view.plotter.renderers]
        assert widths == ([1.0, 0.0] if mode == "lines" else [0.5, 0.5]), mode  # lines: one scene, full width
    view.mode.setCurrentText("coordinates")
    # the mouse on a shape names the vertex under it (the status bar shows it)
    assert view._hover_text(view.plotter.renderers[1], view.shown_points[1][10]) == "vertex 10 of the target (wolf1.off)"
    seen = []
    view.hovered.connect(seen.append)
    widget = view.plotter.interactor
    for x in range(widget.width() // 8, widget.width() // 2, widget.width() // 40):  # across the source
        mouse_event(widget, "move", x, widget.height() // 2)
        qtbot.wait(2 * int(1000 * HOVER_INTERVAL))
    assert seen and all(text.startswith("vertex ") and "of the source (wolf0.off)" in text for text in seen)
    assert window.statusBar().currentMessage() == seen[-1]
    # both linked subplots share the camera
    cams = [r.camera for r in view.plotter.renderers]
    assert all(np.allclose(c.position, cams[0].position) for c in cams)
    window.set_up_axis("+x")
    assert np.allclose(view.displayed.displays[0].rotation[1], [1, 0, 0])
    assert window.up_actions.checkedAction().data() == "+x"
    assert window.compare_view.up == window.sequence_view.up == "+x"
    window.set_up_axis("auto")
    assert np.allclose(view.displayed.displays[0].rotation[1], [0, 0, 1])


def test_a_matched_curve_is_seen_as_the_outline_was_drawn(qtbot, window):
    """A ring round the wolf's body matched to the outline a drawing from above shows: the product view looks
    down at the wolf (the curve in sight along its border), the View menu's presets move the camera, and Reset
    camera returns to the view as drawn. A curve at one vertex has no such view: the front preset."""
    from app.views.camera import ShapeDisplay
    from corrlib.io import load_mesh

    wolf = load_mesh(TOSCA / "wolf0.off")
    points = ShapeDisplay.of(wolf.vertices).points(wolf.vertices)
    ring = np.flatnonzero(np.abs(points[:, 1] - np.median(points[:, 1])) < 0.01)
    ring = ring[np.argsort(np.arctan2(points[ring, 2], points[ring, 0]))]
    outline = points[ring][:, [0, 2]] * np.array([1.0, -1.0])  # (right, up) of the view from above
    view = window.product_view
    window.tabs.setCurrentWidget(view)
    view.show_contour_match(outline, wolf, ring, np.arange(ring.size), 1.0)
    assert np.allclose(camera_direction(view.camera()), [0, 1, 0], atol=1e-9)  # from above
    window.show_view("front")
    assert np.allclose(camera_direction(view.camera()), [0, 0, 1], atol=1e-9)
    window.show_view("reset")
    assert np.allclose(camera_direction(view.camera()), [0, 1, 0], atol=1e-9)
    view.show_contour_match(outline, wolf, np.zeros(ring.size, dtype=int), np.arange(ring.size), 1.0)
    assert view.drawn_frame is None and view.default_view == "front"
    assert np.allclose(camera_direction(view.camera()), [0, 0, 1], atol=1e-9)


def test_camera_save_and_load(qtbot, window, tmp_path):
    with qtbot.waitSignal(window.result_ready, timeout=180_000):
        load_demo(qtbot, window)
        window.run_method(method="descriptor-nn")
    window.tabs.setCurrentWidget(window.pair_view)
    window.show_view("side")
    saved = window.pair_view.camera()
    window.save_camera(str(tmp_path / "side.json"))
    window.show_view("top")
    assert not np.allclose(window.pair_view.camera().position, saved.position)
    window.load_camera(str(tmp_path / "side.json"))
    assert np.allclose(window.pair_view.camera().position, saved.position)
    assert np.allclose(window.pair_view.camera().view_up, saved.view_up)
    # a bad camera file: a named error, the window goes on
    errors = []
    window.error_shown.connect(errors.append)
    (tmp_path / "bad.json").write_text("{}")
    window.load_camera(str(tmp_path / "bad.json"))
    assert errors and "bad.json" in errors[-1]
    window.tabs.setCurrentWidget(window.retrieval_view)  # no 3D camera here
    window.save_camera(str(tmp_path / "none.json"))
    assert not (tmp_path / "none.json").exists() and "no camera to save" in errors[-1]


def test_point_inspection_across_compare_views(qtbot, window):
    """A source vertex marked in every view with each method's partner and the true one (the demo's
    identity ground truth), by a click on the source, a click on a target, or inspect()."""
    load_demo(qtbot, window)
    view = compare(qtbot, window, ("descriptor-nn", "fmap-zoomout"))
    assert view.true_partner is not None and np.array_equal(view.true_partner, np.arange(window.source.n_vertices))
    vertex = 1234
    n_actors = sum(len(r.actors) for r in view.plotter.renderers)
    view.inspect(vertex)
    assert view.captions[0] == f"source: vertex {vertex}"
    for index, row in enumerate(view.rows, 1):
        partner = int(row["result"].map_xy[vertex])
        caption = view.captions[index]
        assert f"{vertex} -> {partner}" in caption and f"true {vertex}" in caption
        error = row["per_vertex"][vertex]
        assert f"error {error:.3f}" in caption
    # one marker on the source, a partner and a true partner on each target
    assert sum(len(r.actors) for r in view.plotter.renderers) == n_actors + 1 + 2 * len(view.rows)

    class Picker:
        def __init__(self, renderer):
            self.renderer = renderer

        def GetRenderer(self):
            return self.renderer

    # a real click in the middle of the source's view (top left of the grid) inspects a source vertex
    widget = view.plotter.interactor
    rows, cols = view.plotter.shape
    x, y = widget.width() // (2 * cols), widget.height() // (2 * rows)
    view.inspect(None)
    mouse_event(widget, "press", x, y)
    mouse_event(widget, "release", x, y)
    qtbot.waitUntil(lambda: view.inspected is not None, timeout=3000)
    assert view.captions[0] == f"source: vertex {view.inspected}"
    src_points, tgt_points = view.framed_points()
    view._on_pick(src_points[77], Picker(view.plotter.renderers[0]))
    assert view.inspected == 77
    # a click on a target vertex inspects the source vertex that method maps there
    row = view.rows[0]
    target_vertex = 500
    view._on_pick(tgt_points[target_vertex], Picker(view.plotter.renderers[1]))
    assert view.inspected == int(row["result"].map_yx[target_vertex])
    assert view._hover_text(view.plotter.renderers[0], src_points[42]) == "vertex 42 of the source (wolf0.off)"
    assert "of the target" in view._hover_text(view.plotter.renderers[1], tgt_points[42])
    # the heat maps show the source: the marker sits on the vertex and the caption gives its error
    view.color_mode.setCurrentText("error heat map")
    view.inspect(vertex)
    assert all(f"vertex {vertex}: error" in view.captions[i] for i in range(1, len(view.rows) + 1))
    with pytest.raises(IndexError):
        view.inspect(window.source.n_vertices)
    view.inspect(None)
    assert view.captions[0] == "source"


def test_picture_exports(qtbot, window, tmp_path):
    from PIL import Image

    load_demo(qtbot, window)
    errors = []
    window.error_shown.connect(errors.append)
    window.save_compare_grid(str(tmp_path / "empty.png"))
    assert errors and "compare grid is empty" in errors[-1] and not (tmp_path / "empty.png").exists()
    view = compare(qtbot, window, ("descriptor-nn",))
    window.save_compare_grid(str(tmp_path / "grid.png"))
    grid = np.asarray(Image.open(tmp_path / "grid.png"))
    assert grid.shape[:2] == tuple(view.plotter.window_size[::-1])
    assert grid[..., :3].std() > 10  # shapes drawn, not a blank picture
    window.save_transparent(str(tmp_path / "clear.png"))
    clear = np.asarray(Image.open(tmp_path / "clear.png"))
    assert clear.shape[2] == 4
    assert clear[0, 0, 3] == 0 and clear[..., 3].max() == 255  # transparent background, opaque shapes
    window.tabs.setCurrentWidget(window.retrieval_view)
    window.save_transparent(str(tmp_path / "none.png"))
    assert "no 3D view" in errors[-1] and not (tmp_path / "none.png").exists()


def test_shortcuts_are_listed_and_work(qtbot, window):
    """Every shortcut is in Help > Keyboard shortcuts, and a key press triggers its action from a widget
    that does not handle the key itself (the method box)."""
    from PySide6.QtCore import Qt
    from PySide6.QtGui import QAction

    listed = dict(window.shortcut_list())
    for action in ("Run method", "Cancel", "Front", "Side", "Top", "Reset camera", "Next tab", "Previous tab",
                   "Keyboard shortcuts"):
        assert action in listed, action
    actions = {a.text(): a for a in window.findChildren(QAction)}
    window.activateWindow()
    qtbot.waitUntil(window.isActiveWindow, timeout=5000)  # shortcuts go to the active window
    window.method_box.setFocus()
    for text, key, modifier in (("Front", Qt.Key_1, Qt.ControlModifier), ("Top", Qt.Key_3, Qt.ControlModifier),
                                ("Next tab", Qt.Key_PageDown, Qt.ControlModifier)):
        with qtbot.waitSignal(actions[text].triggered, timeout=2000):
            qtbot.keyClick(window.method_box, key, modifier)
    window.tabs.setCurrentIndex(0)
    actions["Previous tab"].trigger()
    assert window.tabs.currentIndex() == window.tabs.count() - 1
    actions["Next tab"].trigger()
    assert window.tabs.currentIndex() == 0
    window.show_shortcuts()  # not interactive: written to the job log
    assert "Ctrl+R" in window.job_panel.log.toPlainText()


def test_thumbnails_are_rendered_upright_by_vtk():
    """A standing wolf's thumbnail (front preset, auto up) is wider than tall and its legs are at the bottom:
    more of the bottom row band is background than of the body's band."""
    from io import BytesIO

    from PIL import Image

    from app.views.retrieval import ThumbnailRenderer
    from corrlib.io import load_mesh

    renderer = ThumbnailRenderer(size=200)
    try:
        wolf = load_mesh(TOSCA / "wolf0.off")
        image = np.asarray(Image.open(BytesIO(renderer.png(wolf, np.arange(0, 400, 7)))))[..., :3]
    finally:
        renderer.close()
    shape = np.any(image < 240, axis=2)
    rows, cols = np.flatnonzero(shape.any(axis=1)), np.flatnonzero(shape.any(axis=0))
    width, height = np.ptp(cols) + 1, np.ptp(rows) + 1
    assert width > height and width > 0.85 * 200  # fills the thumbnail across
    crimson = (image[..., 0] > 150) & (image[..., 1] < 80) & (image[..., 2] < 100)
    assert crimson.sum() > 20  # the matched curve is drawn
    top, bottom = rows[0], rows[-1]
    band = (bottom - top) // 5
    upper = shape[top:top + band].mean()
    lower = shape[bottom - band:bottom + 1].mean()
    assert lower < upper  # legs below, the back above


@pytest.mark.parametrize("seed", range(6))
def test_gallery_thumbnails_fill_the_gallery(seed):
    """The thumbnails' side against its definition, by brute force over every side and number of columns:
    the largest at which every item is in sight (capped), else the one whose whole columns fill the width."""
    from app.views.retrieval import gallery_icon_px

    rng = np.random.default_rng(seed)
    spacing, smallest, largest = 8, 120, 320
    for _ in range(200):
        width, height, n, caption = rng.integers(100, 2000), rng.integers(100, 1200), rng.integers(0, 40), 34

        def in_sight(side):
            return any(c * (side + spacing) <= width - spacing
                       and -(-max(n, 1) // c) * (side + spacing + caption) <= height - spacing
                       for c in range(1, max(n, 1) + 1))

        side = gallery_icon_px(width, height, n, caption, spacing=spacing, smallest=smallest, largest=largest)
        largest_in_sight = max((s for s in range(1, largest + 1) if in_sight(s)), default=0)
        if largest_in_sight >= smallest:
            assert side == largest_in_sight
        else:
            usable = width - spacing
            cols = usable // (side + spacing)
            assert side >= min(smallest, usable - spacing) and cols >= 1
            assert usable - cols * (side + spacing) < cols  # no strip is left empty at the right


def test_the_gallery_shows_every_thumbnail_it_can_and_follows_the_window(qtbot):
    """Ten ranked meshes in a retrieval tab: where they fit, all are in sight at more than the smallest side and
    larger in a larger tab; in a small tab the gallery scrolls and its columns span the width."""
    from PySide6.QtCore import Qt
    from PySide6.QtGui import QIcon, QPixmap
    from PySide6.QtWidgets import QListWidgetItem

    from app.views.retrieval import THUMBNAIL_MIN_PX, RetrievalView

    view = keep_widget(RetrievalView())
    view.show()
    for i in range(10):
        item = QListWidgetItem(f"{i + 1}. mesh{i}.off\nscore {i}")
        pixmap = QPixmap(320, 320)
        pixmap.fill(Qt.gray)
        item.setIcon(QIcon(pixmap))
        view.gallery.addItem(item)

    def laid_out(width, height):
        view.resize(width, height)
        qtbot.waitUntil(lambda: view.gallery.width() > width - 60)
        qtbot.wait(50)  # the list lays its items out after the resize
        gallery = view.gallery
        rects = [gallery.visualItemRect(gallery.item(i)) for i in range(gallery.count())]
        return gallery.iconSize().width(), gallery.verticalScrollBar().maximum(), rects

    side, scroll, rects = laid_out(1100, 800)
    assert side > THUMBNAIL_MIN_PX and scroll == 0 and all(view.gallery.viewport().rect().contains(r) for r in rects)
    side, scroll, rects = laid_out(1600, 450)  # the height limits the side: the columns spread over the width
    # (what is left is the scroll bar's room, which a wrapping list keeps: 35 px here, 111 px before)
    assert scroll == 0 and view.gallery.viewport().width() - max(r.right() for r in rects) < 0.4 * side
    larger, scroll, _ = laid_out(1500, 1000)
    assert larger > side and scroll == 0
    side, scroll, rects = laid_out(560, 560)
    assert side >= THUMBNAIL_MIN_PX and scroll > 0
    grid = view.gallery.gridSize().width()
    assert view.gallery.viewport().width() - max(r.right() for r in rects) < grid  # no empty column at the right


def test_the_ranking_is_listed_at_once_and_its_thumbnails_drawn_one_at_a_time(qtbot):
    """A collection of many meshes froze the window while every thumbnail was drawn (about 75 ms each): the
    ranks and scores are listed when the ranking arrives, the thumbnails follow one per turn of the event
    loop, best first, and a new ranking drops the old one's. Found by a review: a collapsed curve was ranked
    without a word, a long name hid the score, a failed mesh's caption floated in an empty cell."""
    from app.views.retrieval import RetrievalView
    from corrlib.io import load_mesh
    from corrlib.retrieval import RetrievalHit

    wolf = load_mesh(TOSCA / "wolf0.off")

    def hit(name, score, **kwargs):
        return RetrievalHit(Path(name), score, path_vertices=np.arange(0, 400, 7), score=score, **kwargs)

    hits = [hit("wolf0.off", 1.0, curve_length_ratio=0.9), hit("wolf1.off", 2.0, curve_length_ratio=0.3),
            hit("a_wolf_with_a_name_far_too_long_for_its_place_in_the_gallery.off", 3.0),
            hit("wolf3.off", 4.0), RetrievalHit(Path("broken.off"), np.inf, "broken.off: no faces", score=np.inf)]
    view = keep_widget(RetrievalView())
    view.resize(700, 600)
    view.show()
    view.show_results(hits, [wolf] * 4 + [None])
    gallery = view.gallery
    assert gallery.count() == 5 and view.thumbnails_pending() == 4
    assert all(gallery.item(i).icon().isNull() for i in range(4))
    assert not gallery.item(4).icon().isNull() and gallery.item(4).text() == "5. broken.off\nnot matched"
    qtbot.waitUntil(lambda: not gallery.item(0).icon().isNull())
    assert gallery.item(3).icon().isNull() or view.thumbnails_pending() == 0  # the best first
    qtbot.waitUntil(lambda: view.thumbnails_pending() == 0)
    assert not any(gallery.item(i).icon().isNull() for i in range(5))
    assert gallery.item(1).text().endswith("score 2 (short curve)")
    assert "probably collapsed" in gallery.item(1).toolTip()
    assert "short curve" not in gallery.item(0).text() + gallery.item(0).toolTip()
    long_name = gallery.item(2).text().splitlines()
    assert "…" in long_name[0] and long_name[1] == "score 3"
    assert gallery.fontMetrics().horizontalAdvance(long_name[0]) <= gallery.iconSize().width()
    view.show_results(hits[:1], [wolf])
    view.clear_results()
    assert view.thumbnails_pending() == 0 and gallery.count() == 0
    qtbot.wait(100)  # the dropped ranking's timer finds nothing to draw


def test_the_compare_table_shows_every_method_in_a_small_window(qtbot):
    """Five methods' rows in a Compare tab of a laptop's size: the table's pane grows until no row is hidden
    (it showed two of five at 1280×720), up to half of the tab; a pane the user made taller stays so."""
    from app.views.compare import COLUMNS, CompareView, table_item

    view = keep_widget(CompareView())
    view.resize(620, 560)
    view.show()
    qtbot.waitUntil(lambda: view.splitter.height() > 300)
    for r, name in enumerate(["kernel-matching", "divergence-free", "fmap-zoomout", "descriptor-nn", "refined"]):
        view.table.insertRow(r)
        for c in range(len(COLUMNS)):
            view.table.setItem(r, c, table_item(name if c == 0 else 0.000532 * (r + 1)))
        view.fit_table()
    qtbot.wait(50)
    assert view.table.verticalScrollBar().maximum() == 0
    assert all(view.table.viewport().rect().contains(view.table.visualItemRect(view.table.item(r, 0)))
               for r in range(5))
    views_px, table_px = view.splitter.sizes()
    assert table_px <= (views_px + table_px) // 2 + 1
    # the method strip holds every method's box, wrapped onto more rows in a narrower tab
    from types import SimpleNamespace

    labels = ["Kernel matching", "Divergence-free deformation", "Functional maps + ZoomOut",
              "Descriptor nearest neighbour", "Product-manifold refinement"]
    view.set_methods([SimpleNamespace(name=label.lower(), label=label) for label in labels])
    for width in (620, 500):
        view.resize(width, 560)
        qtbot.wait(100)
        strip = view.methods
        assert all(strip.viewport().rect().contains(strip.visualItemRect(strip.item(i)))
                   for i in range(strip.count())), width
    view.resize(620, 560)
    qtbot.wait(100)
    views_px, table_px = view.splitter.sizes()
    view.splitter.setSizes([100, views_px + table_px - 100])  # the user drags the table's pane taller
    view.fit_table()
    assert view.splitter.sizes()[0] == 100
    assert view.table.item(0, 1).text() == "0.000532"  # three significant digits


def test_each_thumbnail_is_drawn_with_its_own_camera():
    """The renderer is reused for every thumbnail of a gallery: a thumbnail must be what a fresh renderer draws
    for the same mesh, not the new mesh seen with the previous thumbnail's camera."""
    from io import BytesIO

    from PIL import Image

    from app.views.retrieval import ThumbnailRenderer
    from corrlib.io import load_mesh

    wolf, cat = load_mesh(TOSCA / "wolf0.off"), load_mesh(TOSCA / "cat1.off")

    def pixels(renderer, mesh):
        return np.asarray(Image.open(BytesIO(renderer.png(mesh, None))))[..., :3].astype(int)

    reused, fresh = ThumbnailRenderer(size=120), ThumbnailRenderer(size=120)
    try:
        pixels(reused, wolf)
        after_the_wolf = pixels(reused, cat)
        alone = pixels(fresh, cat)
    finally:
        reused.close()
        fresh.close()
    assert np.abs(after_the_wolf - alone).max() <= 2


def test_a_thumbnail_shows_the_mesh_from_the_view_the_outline_was_drawn_from():
    """A top-view outline's curve on the wolf: the thumbnail is the view from above (the wolf long and narrow,
    its legs hidden under the body), not the front preset's side view; without the outline, the side view."""
    from io import BytesIO

    from PIL import Image

    from app.views.camera import ShapeDisplay
    from app.views.retrieval import ThumbnailRenderer
    from corrlib.io import load_mesh

    wolf = load_mesh(TOSCA / "wolf0.off")
    points = ShapeDisplay.of(wolf.vertices).points(wolf.vertices)
    waist = np.abs(points[:, 1] - np.median(points[:, 1])) < 0.01  # a ring round the body, seen from above
    ring = np.flatnonzero(waist)
    ring = ring[np.argsort(np.arctan2(points[ring, 2], points[ring, 0]))]
    outline = points[ring][:, [0, 2]] * np.array([1.0, -1.0])  # the ring as a drawing from above shows it

    def extent(image):
        shape = np.any(image < 240, axis=2)
        rows, cols = np.flatnonzero(shape.any(axis=1)), np.flatnonzero(shape.any(axis=0))
        return np.ptp(cols) + 1, np.ptp(rows) + 1

    renderer = ThumbnailRenderer(size=200)
    try:
        top = np.asarray(Image.open(BytesIO(renderer.png(wolf, ring, outline=outline))))[..., :3]
        side = np.asarray(Image.open(BytesIO(renderer.png(wolf, ring))))[..., :3]
    finally:
        renderer.close()
    (top_w, top_h), (side_w, side_h) = extent(top), extent(side)
    assert top_w / top_h > 1.4 * side_w / side_h  # from above the wolf is narrower than from the side


def test_a_closed_plotter_leaves_no_python_callback_on_its_widget(qtbot):
    """Qt sends a widget events while it deletes it; a closed plotter's widget must not call into Python then."""
    from PySide6.QtCore import SIGNAL, QObject, QSize
    from PySide6.QtGui import QResizeEvent
    from PySide6.QtWidgets import QApplication, QWidget

    from app.views.scene import close_plotter, make_plotter

    parent = keep_widget(QWidget())
    plotter = make_plotter(parent)
    seen = []

    class Filter(QObject):
        def eventFilter(self, _obj, event):  # noqa: N802 (Qt's name)
            seen.append(event.type())
            return False

    widget = plotter.interactor
    widget.installEventFilter(Filter(widget))
    resize = QResizeEvent(QSize(20, 20), QSize(10, 10))
    QApplication.sendEvent(widget, resize)
    assert seen  # the filter works while the plotter is open
    watchers = parent.receivers(SIGNAL("destroyed(QObject*)"))
    assert watchers >= 1  # VTK's widget closes itself when its parent is destroyed

    close_plotter(plotter)
    seen.clear()
    QApplication.sendEvent(widget, resize)
    assert seen == []
    assert parent.receivers(SIGNAL("destroyed(QObject*)")) == watchers - 1
    close_plotter(plotter)  # closing twice is harmless


def test_the_log_says_when_the_target_overruled_a_side_view():
    """The studio's log line on a 2D-to-3D match names the view and, where the outline alone would have been a
    side view but the target is not thinnest across its plane of symmetry (a person), says so."""
    from types import SimpleNamespace

    from app.jobs import contour_reading

    def reading(view, seen_from_side):
        result = SimpleNamespace(method="contour3d", energy_meaning="paper energy", energy=1.0,
                                 extras={"view": view, "asymmetry": 0.1, "intrinsic_asymmetry": 0.5,
                                         "mesh_seen_from_side": seen_from_side})
        return contour_reading(result)

    assert "not thinnest across its plane of symmetry" in reading("front", False)
    assert "read as a side view" in reading("side", True)
    for view, seen in (("side", True), ("front", None), ("front", True)):
        assert "not thinnest" not in reading(view, seen)


def test_the_log_says_when_the_contour_was_matched_at_fewer_points():
    """A target whose mean edge is longer than the contour's step is matched at fewer points
    (``contour3d.query_for_mesh``); the log line says so and why, and says nothing where all points were used."""
    from types import SimpleNamespace

    from app.jobs import contour_reading

    def reading(used, asked):
        return contour_reading(SimpleNamespace(method="contour3d", energy_meaning="paper energy", energy=1.0,
                                               extras={"contour_points": used, "contour_points_asked": asked}))

    assert "matched at 116 points instead of 200" in reading(116, 200)
    assert "instead of" not in reading(200, 200)


def test_the_log_warns_of_a_matched_curve_short_enough_to_have_collapsed():
    """A second log line, beginning "warning:", where the curve is under half the outline's length."""
    from types import SimpleNamespace

    from app.jobs import contour_reading

    def reading(ratio):
        return contour_reading(SimpleNamespace(method="contour3d", energy_meaning="paper energy", energy=1.0,
                                               extras={"curve_length_ratio": ratio}))

    assert "\nwarning: the matched curve is 0.36 of the outline's length" in reading(0.36)
    assert "warning" not in reading(0.75)


def test_a_mesh_is_shown_alone_until_the_other_comes(qtbot, window):
    """The pair view drew nothing until both meshes were loaded: a user could not see what was loaded (or what
    a repair made of it) before choosing the other."""
    window.load_file(str(TOSCA / "wolf1.off"), "target")
    wait_loaded(qtbot, window)
    view = window.pair_view
    assert len(view.shown_points) == 1 and len(view.shown_points[0]) == window.target.n_vertices
    assert view.info.text() == "Load a source mesh, then run a method."
    assert view.camera() is not None  # framed on the target
    window.load_file(str(TOSCA / "wolf0.off"), "source")
    wait_loaded(qtbot, window)
    assert [len(points) for points in view.shown_points] == [window.source.n_vertices, window.target.n_vertices]
    assert view.info.text() == "Run a method to see the correspondence."
    window.load_file(str(ROOT / "resources" / "data" / "sketch2d" / "human_sketch_a_contour.txt"), "source")
    wait_loaded(qtbot, window)  # a contour is named where the source was, the target drawn alone
    assert len(view.shown_points) == 1 and len(view.shown_points[0]) == window.target.n_vertices
    assert view.info.text() == "The source is a contour: a 2D-to-3D match is shown in the Product tab."


def test_a_planar_sketch_mesh_is_the_query_as_a_source_and_a_mesh_as_a_target(qtbot, window):
    """The paper's sketches are flat triangulated meshes: ``corr match-contour`` takes one as the query (its
    outline), and so does the studio's source; as the target it stays the mesh it is."""
    from corrlib.shapes import Contour2D, TriMesh

    sketch = ROOT / "resources" / "data" / "sketch2d" / "human_sketch_a.off"
    window.load_file(str(TOSCA / "wolf0.off"), "target")
    window.load_file(str(sketch), "source")
    wait_loaded(qtbot, window)
    assert isinstance(window.source, Contour2D) and window.source.name == "human_sketch_a.off"
    assert "the outline of a planar sketch mesh (895 vertices)" in window.source_info.text()
    assert window.sketch.status.text() == f"human_sketch_a.off: {window.source.n_points} points, loaded as the query"
    assert window.retrieval_view.query is window.source
    assert "contour3d" in [window.method_box.itemData(i) for i in range(window.method_box.count())]
    window.load_file(str(sketch), "target")
    wait_loaded(qtbot, window)
    assert isinstance(window.target, TriMesh) and window.target.n_vertices == 895


def test_the_query_contour_fills_its_viewport_after_a_resize_and_a_redraw(qtbot, window):
    """Found by fuzzing: the contour's camera came from VTK's reset, which fits the window size VTK last rendered
    at: right after a resize the fit was the old one, and after the next render a redraw divided by the narrow
    viewport's aspect, so the contour showed at about half its size. Its box now fills the width or the height."""
    from app.views.camera import caption_band, viewport_aspect
    from corrlib.io import load_mesh

    wolf = load_mesh(TOSCA / "wolf0.off")
    angles = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    outline = np.column_stack([np.cos(angles), 2 * np.sin(angles)])
    view = window.product_view
    window.tabs.setCurrentWidget(view)
    view.show_contour_match(outline, wolf, np.arange(60), np.arange(60), 1.0)

    def fills_its_viewport():
        renderer = view.plotter.renderers[0]
        camera = renderer.camera
        half_height = np.linalg.norm(np.subtract(camera.position, camera.focal_point)) * \
            np.tan(np.radians(camera.view_angle) / 2)
        needed = 1.05 * max(1.0 / viewport_aspect(view.plotter, renderer),  # fitted_camera's margin
                            2.0 / (1 - caption_band(view.plotter, renderer)))
        return half_height == pytest.approx(needed, rel=1e-6)

    for size in ((1280, 720), (900, 700)):
        window.resize(*size)
        qtbot.wait(300)
        assert fills_its_viewport(), size
        view.plotter.render()
        view.redraw()
        assert fills_its_viewport(), size


def test_captions_side_by_side_have_one_size_and_are_shortened_to_their_view(qtbot, window):
    """The query's short caption and the mesh's long one were drawn at different sizes (VTK's corner annotation
    shrinks a long line to its view). Both now have the caption's pixel size: measured on the rendered picture,
    the text rows of the two views' top bands are equally high; a line wider than its view ends in an ellipsis."""
    from corrlib.io import load_mesh

    wolf = load_mesh(TOSCA / "wolf0.off")
    angles = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    view = window.product_view
    window.tabs.setCurrentWidget(view)
    window.resize(1280, 720)
    view.show_contour_match(np.column_stack([np.cos(angles), 2 * np.sin(angles)]), wolf, np.arange(40),
                            np.arange(40), 12.5)
    qtbot.wait(300)
    view.plotter.render()
    image = np.asarray(view.plotter.screenshot(return_img=True))
    heights = []
    for renderer in view.plotter.renderers[:2]:
        x0, y0, x1, y1 = renderer.GetViewport()
        h, w = image.shape[:2]
        band = image[int((1 - y1) * h):int((1 - y1) * h) + 30, int(x0 * w):int(x1 * w)]
        rows = np.flatnonzero((band.min(axis=2) < 128).any(axis=1))  # dark text on the light background
        heights.append(rows.max() - rows.min() + 1)
    assert abs(heights[0] - heights[1]) <= 1 and heights[0] >= 9, heights  # a pixel for the letters' ascenders

    from app.views.scene import elided_caption

    assert elided_caption("query contour", 400, 13) == "query contour"
    cut = elided_caption("matched curve, energy 12.5: a mesh with a very long file name.off", 200, 13)
    assert cut.endswith("…") and len(cut) == int(200 / (0.55 * 13)) - 1
    assert elided_caption("a long first line of a caption\nshort", 100, 13).split("\n")[1] == "short"


def test_a_long_file_name_is_shortened_in_the_shapes_panel(qtbot, window, tmp_path):
    """A label wraps only between words: one long file name widened the Shapes panel past its edge and cut every
    line of it. Words longer than the panel's share are shortened in their middle; the tooltip has them whole."""
    from app.jobs import SHAPES_WORD_CHARS, shortened_words

    assert shortened_words("human0.off: 4876 vertices") == "human0.off: 4876 vertices"
    name = "a_very_long_file_name_for_a_mesh_to_test_captions.off"
    short = shortened_words(f"{name}: 4876 vertices")
    assert short == "a_very_long_fi…_captions.off: 4876 vertices" and len(short.split()[0]) <= SHAPES_WORD_CHARS
    (tmp_path / name).write_bytes((TOSCA / "wolf0.off").read_bytes())
    window.load_file(str(tmp_path / name), "source")
    wait_loaded(qtbot, window)
    assert window.source_info.text().startswith("a_very_long_fi…_captions.off: 4344 vertices")
    assert window.source_info.toolTip().startswith(f"{name}: 4344 vertices")


def test_a_view_keeps_one_caption_observer_however_often_it_is_captioned():
    """A caption is fitted to its view at every render; a view captioned again (the Compare grid at every
    inspected vertex) must not keep fitting the captions it had."""
    import pyvista as pv

    from app.views.scene import add_caption

    plotter = pv.Plotter(off_screen=True)
    renderer = plotter.renderer
    for i in range(5):
        add_caption(plotter, f"caption {i}")
    renderer.RemoveObserver(renderer._caption_observer)
    assert not renderer.HasObserver("StartEvent")  # the four before it were removed as it came
    plotter.close()


def test_the_methods_unticked_for_a_comparison_stay_unticked_for_the_next_pair(qtbot, window):
    """Found by fuzzing the studio: every load ticked every method of the Compare tab again, the slow ones too."""
    from PySide6.QtCore import Qt

    load_demo(qtbot, window)
    methods = window.compare_view.methods
    names = [methods.item(i).data(Qt.UserRole) for i in range(methods.count())]
    assert "kernel-matching" in names and "divergence-free" in names
    for i in range(methods.count()):
        if methods.item(i).data(Qt.UserRole) in ("kernel-matching", "divergence-free"):
            methods.item(i).setCheckState(Qt.Unchecked)
    window.load_file(str(TOSCA / "cat0.off"), "target")
    wait_loaded(qtbot, window)
    assert sorted(window.compare_view.selected()) == sorted(set(names) - {"kernel-matching", "divergence-free"})
    window.load_file(str(ROOT / "resources" / "data" / "sketch2d" / "human_sketch_a_contour.txt"), "source")
    window.load_file(str(TOSCA / "wolf0.off"), "source")  # no mesh pair in between: remembered all the same
    wait_loaded(qtbot, window)
    assert sorted(window.compare_view.selected()) == sorted(set(names) - {"kernel-matching", "divergence-free"})


def test_the_sequence_description_does_not_widen_the_window(qtbot, window):
    """The sequence of a map without a deformation is described in a long line; unwrapped, it raised the window's
    minimum width to 1,461 pixels, wider than a 1280 × 720 screen."""
    from app.jobs import sequence_options
    from corrlib.methods.base import MatchResult

    load_demo(qtbot, window)
    narrowest = window.minimumSizeHint().width()
    ident = np.arange(window.source.n_vertices)
    result = MatchResult("descriptor-nn", ident, ident)
    window.sequence_view.set_sequences(window.source, sequence_options(result, window.source, window.target))
    qtbot.wait(50)
    assert "as-rigid-as-possible" in window.sequence_view.kind.text()
    assert window.minimumSizeHint().width() <= max(narrowest, 1280)


def test_a_map_from_a_file_is_shown_like_a_result(qtbot, window, tmp_path):
    """File ▸ Open a map of this pair…: another tool's map is coloured, scored against the ground truth and
    interpolated as a method's result is; a map that does not fit, or a saved result of another pair, is said,
    naming the file."""
    from corrlib.io import save_map

    messages = []
    window.error_shown.connect(messages.append)
    window.load_map(str(tmp_path / "nothing.txt"))
    assert messages and "two meshes" in messages[-1]
    load_demo(qtbot, window)
    identity = save_map(tmp_path / "identity.txt", np.arange(window.source.n_vertices))  # the demo pair's truth
    with qtbot.waitSignal(window.result_ready, timeout=60_000):
        window.load_map(str(identity))
    assert window.last_result.method == "the map identity.txt"
    assert window.pair_view.info.text().startswith("the map identity.txt, mean geodesic error 0.0000")
    assert window.pair_view.target_colors is not None and window.pair_view.target_colors.std(axis=0).min() > 0.1
    assert "error: mean 0.000" in window.job_panel.log.toPlainText()
    view = window.sequence_view
    assert "as-rigid-as-possible" in view.kind.text()
    assert np.allclose(view.positions(1.0), window.target.vertices, atol=1e-6)
    short = save_map(tmp_path / "short.txt", np.arange(10))
    window.load_map(str(short))
    qtbot.waitUntil(lambda: any("short.txt" in m for m in messages), timeout=30_000)
    assert "map has 10 entries but the source has" in messages[-1]
    from corrlib.methods import solve

    # a result of the reversed pair: its size fits, its record says it is not this pair's map
    solve("descriptor-nn", window.target, window.source).save(tmp_path / "reversed")
    window.load_map(str(tmp_path / "reversed.npz"))
    qtbot.waitUntil(lambda: any("reversed.npz" in m for m in messages), timeout=30_000)
    assert f"computed for the source {window.target.name!r}" in messages[-1]
    assert window.last_result.method == "the map identity.txt"  # the shown result stays


def test_a_map_opened_for_the_pair_is_compared_with_the_methods(qtbot, window, tmp_path):
    from corrlib.io import save_map

    load_demo(qtbot, window)
    identity = save_map(tmp_path / "identity.txt", np.arange(window.source.n_vertices))
    with qtbot.waitSignal(window.result_ready, timeout=60_000):
        window.load_map(str(identity))
    view = compare(qtbot, window, ["descriptor-nn"])
    rows = {row["method"]: row for row in view.rows}
    assert set(rows) == {"descriptor-nn", "the map identity.txt"}
    assert rows["the map identity.txt"]["mean"] == 0.0 and rows["descriptor-nn"]["mean"] > 0.0
    window.load_file(str(TOSCA / "wolf1.off"), "source")  # another pair: the map is not its map
    wait_loaded(qtbot, window)
    assert window.map_files == []


def test_the_product_layout_draws_the_smaller_shape_larger():
    """Worked by hand: two shapes twice as wide as tall in a 600 × 600 plot are drawn 300 px wide side by side
    (300 × 600 viewports) and 600 px wide stacked (600 × 300), so they are stacked; two shapes twice as tall
    as wide are drawn 600 px tall side by side and 300 px stacked; a tie stays side by side."""
    from app.views.product import SIDE_BY_SIDE, STACKED, drawn_scale, product_layout

    assert drawn_scale((2.0, 1.0), (300, 600)) == 150 and drawn_scale((2.0, 1.0), (600, 300)) == 300
    assert product_layout([(2.0, 1.0), (2.0, 1.0)], (600, 600)) is STACKED
    assert product_layout([(1.0, 2.0), (1.0, 2.0)], (600, 600)) is SIDE_BY_SIDE
    assert product_layout([(1.0, 1.0), (1.0, 1.0)], (600, 300)) is SIDE_BY_SIDE  # 300 px against 150 stacked
    assert product_layout([(1.0, 1.0), (1.0, 1.0)], (600, 600)) is SIDE_BY_SIDE  # 300 either way: a tie
    # the smaller of the two decides: a tall contour beside a wide mesh in a wide plot
    assert product_layout([(1.0, 3.0), (3.0, 1.0)], (1200, 400)) is SIDE_BY_SIDE


def test_an_animal_seen_from_the_side_is_drawn_below_its_outline(qtbot, window):
    """A side view of the wolf in the product view: both shapes are wide, so the outline is drawn above the mesh
    (each viewport the whole width), and side by side again in a plot wide enough for both."""
    from app.views.camera import ShapeDisplay
    from app.views.product import SIDE_BY_SIDE, STACKED
    from corrlib.io import load_mesh

    wolf = load_mesh(TOSCA / "wolf0.off")
    points = ShapeDisplay.of(wolf.vertices).points(wolf.vertices)
    rim = np.flatnonzero(np.abs(points[:, 2]) < 0.01)  # the section by the plane of the side view
    rim = rim[np.argsort(np.arctan2(points[rim, 1], points[rim, 0]))]
    view = window.product_view
    window.tabs.setCurrentWidget(view)
    window.resize(1280, 720)
    qtbot.wait(300)
    view.show_contour_match(points[rim, :2], wolf, rim, np.arange(rim.size), 1.0)
    qtbot.wait(300)  # the plot laid out at its size

    def viewports():
        return tuple(tuple(renderer.GetViewport()) for renderer in view.plotter.renderers[:2])

    assert viewports() == STACKED
    window.resize(1900, 420)  # a plot several times as wide as tall
    qtbot.waitUntil(lambda: viewports() == SIDE_BY_SIDE, timeout=5000)


def test_a_matched_curve_is_lifted_off_the_surface_along_the_outward_normals():
    """On a sphere of radius 1 the curve's points lie at 1 + lift, also where the faces are oriented inward."""
    from app.views.scene import lifted_curve, outward_normals
    from corrlib.shapes import TriMesh
    import pyvista as pv

    sphere = pv.Sphere(radius=1.0, theta_resolution=24, phi_resolution=24).triangulate().clean()
    vertices, faces = np.asarray(sphere.points, dtype=float), np.asarray(sphere.faces).reshape(-1, 4)[:, 1:]
    path = np.arange(0, vertices.shape[0], 5)
    for f in (faces, faces[:, ::-1]):
        mesh = TriMesh(vertices, f)
        curve = lifted_curve(vertices, outward_normals(mesh), path, 0.05)
        assert np.allclose(np.linalg.norm(curve.points, axis=1), 1.05, atol=2e-3)
        assert curve.n_points == path.size


def test_a_curve_along_the_outline_of_the_thumbnail_is_in_sight(monkeypatch):
    """A curve along the wolf's back, which the side view sees edge-on: lifted off the surface it shows along
    the back's outline; drawn on the surface, the body hides a good part of the same tube."""
    from io import BytesIO

    from PIL import Image

    from app.views import retrieval, scene
    from app.views.camera import ShapeDisplay
    from corrlib.io import load_mesh

    wolf = load_mesh(TOSCA / "wolf0.off")
    points = ShapeDisplay.of(wolf.vertices).points(wolf.vertices)
    middle = np.flatnonzero(np.abs(points[:, 2]) < 0.01)
    back = middle[points[middle, 1] > np.percentile(points[:, 1], 60)]
    back = back[np.argsort(points[back, 0])]

    def crimson_pixels():
        renderer = retrieval.ThumbnailRenderer(size=200)
        try:
            image = np.asarray(Image.open(BytesIO(renderer.png(wolf, back))))[..., :3].astype(int)
        finally:
            renderer.close()
        return int(((image[..., 0] > 150) & (image[..., 1] < 80) & (image[..., 2] < 100)).sum())

    lifted = crimson_pixels()
    on_surface = scene.lifted_curve
    monkeypatch.setattr(scene, "lifted_curve", lambda p, n, path, lift, closed=True: on_surface(p, n, path, 0.0, closed))
    assert lifted > 300 and lifted > 1.25 * crimson_pixels()


def test_the_sequence_keeps_its_extrapolation_in_view_and_names_both_shapes(qtbot, window):
    """Found by a review: at the slider's end (t max 1.5 by default) the extrapolated wolf stood below the view,
    which was fitted to t = 0 and 1 only, and the caption named the source alone. The camera is fitted to the
    pose at t max too, again when t max changes, and the caption names the source and the target."""
    from app.jobs import sequence_options
    from corrlib.methods.base import MatchResult

    load_demo(qtbot, window)
    view = window.sequence_view
    ident = np.arange(window.source.n_vertices)
    options = sequence_options(MatchResult("descriptor-nn", ident, ident), window.source, window.target)
    view.t_max.setValue(1.5)
    view.set_sequences(window.source, options, window.target)
    assert view.caption == "wolf0.off to wolf1.off"
    assert len(view.ends) == 3
    assert np.allclose(view.ends[2], view.display.points(view.positions(1.5)))
    view.t_max.setValue(2.0)
    assert np.allclose(view.ends[2], view.display.points(view.positions(2.0)))
    view.t_max.setValue(1.0)
    assert len(view.ends) == 2  # no extrapolation: the source and the target pose
    at_one = view.camera()
    view.t_max.setValue(2.0)  # the camera, still at its preset, is fitted again to the farther pose
    assert not np.allclose(view.camera().position, at_one.position)


def test_the_studio_command_line_refuses_a_method_or_tab_it_does_not_know(capsys):
    """Found by a review: ``--method`` with an unknown name ended in a KeyError traceback, and an unknown ``--tab``
    was ignored. Both stop before a window opens, naming what exists."""
    from app.main import main

    assert main(["--demo", "--method", "Contour3D"]) == 2
    assert "unknown method 'Contour3D' (available: contour-views" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stop:
        main(["--demo", "--tab", "torus"])
    assert stop.value.code == 2 and "invalid choice: 'Torus'" in capsys.readouterr().err


def test_an_unknown_method_asked_of_the_window_is_an_error_not_a_traceback(qtbot, window):
    messages = []
    window.error_shown.connect(messages.append)
    load_demo(qtbot, window)
    window.run_method(method="nosuch")
    assert messages and messages[-1].startswith("unknown method 'nosuch' (available: ")
