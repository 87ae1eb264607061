"""The studio's main window: docks (shapes, sketch, method, job), views (tabs), menus, exports."""

from __future__ import annotations

import csv
import io
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from PySide6.QtCore import QSettings, Qt, QTimer, Signal
from PySide6.QtGui import QAction, QGuiApplication, QKeySequence
from PySide6.QtWidgets import (
    QComboBox,
    QDockWidget,
    QFileDialog,
    QLabel,
    QMainWindow,
    QMessageBox,
    QPlainTextEdit,
    QProgressBar,
    QPushButton,
    QScrollArea,
    QSizePolicy,
    QStackedWidget,
    QTabWidget,
    QVBoxLayout,
    QWidget,
)

import corrlib
from app.gui_gc import STUDIO_THREAD_PREFIX, collect_on_gui_thread
from app.jobs import (LoadedShape, MethodOutcome, contour_reading, describe, load_job, map_job, method_job, repair_job,
                      shortened_words)
from app.param_form import ParamForm
from app.sketch import SketchPanel
from app.views import TAB_NAMES
from app.views.compare import CompareView
from app.views.pair import PairView
from app.views.product import ProductView
from app.views.retrieval import RetrievalView, retrieval_job
from app.views.sequence import SequenceView
from app.worker import SHUTDOWN_TIMEOUT_S, JobRunner, progress_text
from corrlib.errors import CorrError
from corrlib.io import CONTOUR_SUFFIXES, dialog_filter
from corrlib.methods import all_methods, methods_for
from corrlib.shapes import REPAIR_ADVICE, Contour2D, TriMesh

MESH_FILTER = dialog_filter("mesh", all_files=False)  # file-dialog filters: from corrlib.io.FORMATS
CONTOUR_FILTER = dialog_filter("contour", all_files=False)

DEFAULT_WINDOW_SIZE = (1500, 950)  # without a screen to measure
#: on first start the window takes this share of the screen's available width and height
DEFAULT_SCREEN_SHARE = 0.92


def _scrollable(widget: QWidget) -> QScrollArea:
    """``widget`` in a frameless scroll area: a dock may then be smaller than its content (small screens)."""
    area = QScrollArea()
    area.setWidget(widget)
    area.setWidgetResizable(True)
    area.setFrameShape(QScrollArea.NoFrame)
    # vertical scrolling only: the dock keeps the width its content needs
    area.setHorizontalScrollBarPolicy(Qt.ScrollBarAlwaysOff)
    area.setMinimumWidth(widget.minimumSizeHint().width() + area.verticalScrollBar().sizeHint().width())
    return area
PROGRESS_STEPS = 1000  # resolution of the job panel's progress bar
WARM_UP_DELAY_MS = 300  # start loading the compiled kernels this long after the window opened
STALL_PROBE_MS = 20  # the job panel's timer period: a longer gap between ticks is a GUI stall
LOG_MAX_LINES = 2000
MAX_RECENT_FILES = 10
N_EXPORT_FRAMES = 11  # morph frames written by Export > Morph frames (t = 0 .. t max)
ABOUT_PROVENANCE_CHARS = 3000  # how much of the data provenance the About box shows
#: job keys; one job at a time per key (a new job with a running key supersedes it)
LOAD_KEY, PAIR_KEY, COMPARE_KEY, RETRIEVAL_KEY = "load", "pair", "compare", "retrieval"
#: how the job panel names each kind of job
JOB_NAMES = {LOAD_KEY: "loading", PAIR_KEY: "the method", COMPARE_KEY: "the comparison", RETRIEVAL_KEY: "the ranking"}


class JobPanel(QWidget):
    """Progress bar, stage text, elapsed time, cancel button, log; measures GUI stalls during jobs."""

    cancel_requested = Signal()

    def __init__(self, parent=None):
        super().__init__(parent)
        self.bar = QProgressBar()
        self.bar.setRange(0, PROGRESS_STEPS)
        self.stage = QLabel("idle")
        self.stage.setWordWrap(True)
        self.elapsed = QLabel("")
        self.cancel = QPushButton("Cancel")
        self.cancel.setEnabled(False)
        self.cancel.clicked.connect(self.cancel_requested)
        self.log = QPlainTextEdit()
        self.log.setReadOnly(True)
        self.log.setMaximumBlockCount(LOG_MAX_LINES)
        # the log follows its last line unless the reader scrolled up, also when a dock resize grows its range
        self._follow_log = True
        bar = self.log.verticalScrollBar()
        bar.valueChanged.connect(lambda value: setattr(self, "_follow_log", value >= bar.maximum() - 2))
        bar.rangeChanged.connect(lambda low, high: bar.setValue(high) if self._follow_log else None)
        layout = QVBoxLayout(self)
        for w in (self.bar, self.stage, self.elapsed, self.cancel):
            layout.addWidget(w)
        layout.addWidget(self.log, 1)
        self._start = None
        self._last_tick = None
        self.max_stall = 0.0  # longest gap between GUI timer ticks while a job ran (seconds)
        self.max_stall_stage = ""  # the stage shown when it happened
        self.timer = QTimer(self)
        self.timer.setInterval(STALL_PROBE_MS)
        self.timer.timeout.connect(self._tick)

    def started(self, text: str) -> None:
        self._start = self._last_tick = time.perf_counter()
        self.max_stall = 0.0
        self.max_stall_stage = ""
        self.bar.setRange(0, PROGRESS_STEPS)
        self.bar.setValue(0)
        self.bar.setFormat("%p%")
        self.stage.setText(text)
        self.cancel.setEnabled(True)
        self.timer.start()
        self.write(text)

    def report(self, report) -> None:
        if report.fraction >= 0:
            self.bar.setRange(0, PROGRESS_STEPS)
            self.bar.setValue(int(PROGRESS_STEPS * report.fraction))
        else:
            self.bar.setRange(0, 0)  # busy indicator
        self.stage.setText(progress_text(report))
        if report.message:
            self.write(progress_text(report))

    def stopped(self, text: str, still_running: tuple[str, ...] = (), finished: bool = True) -> None:
        """A job ended (``text`` says how); ``still_running`` names the jobs that go on, which keep Cancel. A job
        that failed or was cancelled (not ``finished``) leaves the bar empty with ``text`` in it, not at 100 %."""
        self.bar.setRange(0, PROGRESS_STEPS)
        self.bar.setValue(PROGRESS_STEPS if finished else 0)
        self.bar.setFormat("%p%" if finished else text)
        took = time.perf_counter() - self._start if self._start else 0.0
        self.write(f"{text} ({took:.2f} s; longest GUI stall {1000 * self.max_stall:.0f} ms)")
        if still_running:
            text += f"; still running: {', '.join(still_running)}"
        else:
            self.timer.stop()
        self.cancel.setEnabled(bool(still_running))
        self.stage.setText(text)

    def _tick(self) -> None:
        now = time.perf_counter()
        stall = now - self._last_tick - self.timer.interval() / 1000.0
        if stall > self.max_stall:
            self.max_stall, self.max_stall_stage = stall, self.stage.text()
        self._last_tick = now
        self.elapsed.setText(f"elapsed {now - self._start:.1f} s")

    def write(self, text: str) -> None:
        self.log.appendPlainText(f"[{time.strftime('%H:%M:%S')}] {text}")


#: how long the status bar shows the vertex under the mouse (milliseconds)
HOVER_MESSAGE_MS = 3000


class MainWindow(QMainWindow):
    """The studio. ``result_ready`` fires when a pair/contour result is on screen.

    Files are read and validated, methods solved and their errors measured in
    :class:`JobRunner` threads (factories in :mod:`app.jobs`); the slots here
    only draw. ``loading_finished`` fires when the queue of files to load is empty.
    """

    result_ready = Signal(object)
    error_shown = Signal(str)
    loading_finished = Signal()

    def __init__(self, settings: QSettings | None = None, interactive: bool = True):
        super().__init__()
        self.setWindowTitle("corr studio")
        self.settings = settings or QSettings("corrlib", "corr-studio")
        self.interactive = interactive  # False in tests/screenshots: errors go to the log, not modal dialogs
        self.source = self.target = None
        self.gt: tuple | None = None  # (source rows, target rows, target mirrored rows or None)
        self.shape_paths: dict[str, Path | None] = {"source": None, "target": None}  # files the shapes came from
        self.last_result = None
        self._collector = collect_on_gui_thread(self)  # no cyclic GC on worker threads (see app.gui_gc)
        self._closed = False
        self._warm_up_thread = None  # started once the window is idle (_warm_up)
        self.runner = JobRunner(self)
        self.runner.progress.connect(self._on_progress)
        self.runner.finished.connect(self._on_finished)
        self.runner.failed.connect(self._on_failed)
        self.runner.cancelled.connect(self._on_cancelled)
        self._compare_queue: list[tuple[str, str]] = []  # ("method", name) or ("map", file)
        self._compare_current = ""  # the compared method or map running (named in its failure)
        self.map_files: list[str] = []  # maps of this pair opened from files: compared with the methods
        # files waiting to be loaded (one load job at a time, in request order): (path, which, then, job factory)
        self._load_queue: list[tuple[str, str, Callable[[], None] | None, object]] = []
        self._loading: tuple[str, str, Callable[[], None] | None, object] | None = None

        self.tabs = QTabWidget()
        self.pair_view = PairView()
        self.product_view = ProductView()
        self.sequence_view = SequenceView()
        self.retrieval_view = RetrievalView()
        self.compare_view = CompareView()
        for name, view in zip(TAB_NAMES, (self.pair_view, self.product_view, self.sequence_view,
                                          self.retrieval_view, self.compare_view)):
            self.tabs.addTab(view, name)
        self.setCentralWidget(self.tabs)
        self.retrieval_view.run_requested.connect(self.run_retrieval)
        self.retrieval_view.open_pair.connect(self.open_retrieved_pair)
        self.compare_view.run_button.clicked.connect(self.run_compare)
        for view in (self.pair_view, self.compare_view):
            view.hovered.connect(lambda text: self.statusBar().showMessage(text, HOVER_MESSAGE_MS))

        self._build_docks()
        self._build_menus()
        self.statusBar().showMessage("Load shapes (File menu, drag and drop) or open the demo pair.")
        self.setAcceptDrops(True)
        self.resize(*self._default_size())
        state = self.settings.value("window/state")
        geometry = self.settings.value("window/geometry")
        if geometry is not None:
            self.restoreGeometry(geometry)
        if state is not None:
            self.restoreState(state)
        self._fit_to_screen()
        self.refresh_methods()
        # load the compiled kernels while the window is idle, not during the first solve
        QTimer.singleShot(WARM_UP_DELAY_MS, self._warm_up)

    def _default_size(self) -> tuple[int, int]:
        """Most of the screen (the 3D views get the space), or :data:`DEFAULT_WINDOW_SIZE` without a screen."""
        screen = QGuiApplication.primaryScreen()
        if screen is None:
            return DEFAULT_WINDOW_SIZE
        area = screen.availableGeometry()
        return int(area.width() * DEFAULT_SCREEN_SHARE), int(area.height() * DEFAULT_SCREEN_SHARE)

    def _fit_to_screen(self) -> None:
        """Shrink the window (default or restored size) to the screen's available area, and keep it on it."""
        screen = self.screen() or QGuiApplication.primaryScreen()
        if screen is None:
            return
        area = screen.availableGeometry()
        width, height = min(self.width(), area.width()), min(self.height(), area.height())
        if (width, height) != (self.width(), self.height()):
            self.resize(width, height)
        x = min(max(self.x(), area.x()), area.x() + area.width() - width)
        y = min(max(self.y(), area.y()), area.y() + area.height() - height)
        self.move(x, y)

    def _warm_up(self) -> None:
        import threading

        from corrlib.warmup import warm_up

        if self._closed:
            return  # closed before the timer fired: a thread started now would outlive the window
        self._warm_up_thread = threading.Thread(target=warm_up, name=f"{STUDIO_THREAD_PREFIX}warm-up", daemon=True)
        self._warm_up_thread.start()

    # ------------------------------------------------------------------ layout

    def _build_docks(self) -> None:
        shapes = QWidget()
        lay = QVBoxLayout(shapes)
        self.source_info = QLabel("source: none")
        self.target_info = QLabel("target: none")
        for label in (self.source_info, self.target_info):
            label.setWordWrap(True)
            label.setTextInteractionFlags(Qt.TextSelectableByMouse)
        b_src = QPushButton("Load source…")
        b_src.clicked.connect(lambda: self.open_dialog("source"))
        b_tgt = QPushButton("Load target…")
        b_tgt.clicked.connect(lambda: self.open_dialog("target"))
        b_demo = QPushButton("Demo pair (wolf)")
        b_demo.clicked.connect(self.load_demo)
        from corrlib.resources import bundled_shapes

        self.bundled = QComboBox()
        self.bundled.addItem("bundled shapes…", None)
        for label, rel in bundled_shapes():
            self.bundled.addItem(label, rel)
        b_bsrc = QPushButton("as source")
        b_bsrc.clicked.connect(lambda: self.load_bundled("source"))
        b_btgt = QPushButton("as target")
        b_btgt.clicked.connect(lambda: self.load_bundled("target"))
        for w in (b_src, self.source_info, b_tgt, self.target_info, b_demo, self.bundled, b_bsrc, b_btgt):
            lay.addWidget(w)
        lay.addStretch(1)
        self.sketch = SketchPanel()
        self.sketch.contour_ready.connect(self.use_sketch)
        method = QWidget()
        mlay = QVBoxLayout(method)
        self.method_box = QComboBox()
        self.method_box.currentIndexChanged.connect(self._on_method_changed)
        self.method_desc = QLabel("")
        self.method_desc.setWordWrap(True)
        self.forms = QStackedWidget()
        self._forms: dict[str, ParamForm] = {}
        for spec in all_methods():
            form = ParamForm(spec.params)
            self._forms[spec.name] = form
            self.forms.addWidget(form)
        self.run_button = QPushButton("Run")
        self.run_button.clicked.connect(self.run_method)
        for w in (self.method_box, self.method_desc, self.forms, self.run_button):
            mlay.addWidget(w)
        mlay.addStretch(1)
        self.job_panel = JobPanel()
        self.job_panel.cancel_requested.connect(self.cancel_jobs)
        for title, widget, area in (("Shapes", shapes, Qt.LeftDockWidgetArea),
                                    ("Sketch", self.sketch, Qt.LeftDockWidgetArea),
                                    ("Method", method, Qt.RightDockWidgetArea),
                                    ("Job", self.job_panel, Qt.RightDockWidgetArea)):
            dock = QDockWidget(title, self)
            dock.setObjectName(f"dock-{title}")
            dock.setWidget(_scrollable(widget))
            self.addDockWidget(area, dock)

    def _build_menus(self) -> None:
        file_menu = self.menuBar().addMenu("&File")
        for text, slot, shortcut in (("Open source…", lambda: self.open_dialog("source"), QKeySequence.Open),
                                     ("Open target…", lambda: self.open_dialog("target"), None),
                                     ("Open contour / silhouette…", self.open_contour_dialog, None),
                                     ("Repair and open a mesh…", self.repair_dialog, None),
                                     ("Load ground truth (.vts pair)…", self.open_gt_dialog, None),
                                     ("Open a map of this pair…", self.open_map_dialog, None),
                                     ("Texture image…", self.open_texture_dialog, None),
                                     ("Demo pair", self.load_demo, None),
                                     ("Try retrieval (bundled collection)", self.try_retrieval, None)):
            action = QAction(text, self)
            action.triggered.connect(slot)
            if shortcut is not None:
                action.setShortcut(shortcut)
            file_menu.addAction(action)
        self.recent_menu = file_menu.addMenu("Recent")
        self._fill_recent()
        export = file_menu.addMenu("Export")
        for text, slot in (("Map (text)…", lambda: self.export_map("txt")),
                           ("Result (.npz + .json)…", lambda: self.export_map("npz")),
                           ("Coloured target (PLY)…", self.export_colored),
                           ("Morph frames (OBJ)…", lambda: self.export_frames(".obj")),
                           ("Morph frames (PLY)…", lambda: self.export_frames(".ply")),
                           ("Sequence picture strip (PNG)…", self.export_strip),
                           ("Screenshot of the view (PNG)…", self.export_screenshot),
                           ("3D view, transparent background (PNG)…", self.export_transparent),
                           ("Compare grid as one picture (PNG)…", self.export_compare_grid),
                           ("Comparison table (CSV)…", self.export_table)):
            action = QAction(text, self)
            action.triggered.connect(slot)
            export.addAction(action)
        quit_action = QAction("Quit", self)
        quit_action.setShortcut(QKeySequence.Quit)
        quit_action.triggered.connect(self.close)
        file_menu.addAction(quit_action)
        run_menu = self.menuBar().addMenu("&Run")
        for text, slot, shortcut in (("Run method", self.run_method, "Ctrl+R"), ("Cancel", self.cancel_jobs, "Esc")):
            run_menu.addAction(self._action(text, slot, shortcut))
        self._build_view_menu()
        help_menu = self.menuBar().addMenu("&Help")
        help_menu.addAction(self._action("Keyboard shortcuts", self.show_shortcuts, "F1"))
        about = QAction("About", self)
        about.triggered.connect(self.show_about)
        help_menu.addAction(about)
        toolbar = self.addToolBar("Main")
        toolbar.setObjectName("toolbar-main")
        for text, slot in (("Source…", lambda: self.open_dialog("source")), ("Target…", lambda: self.open_dialog("target")),
                           ("Run", self.run_method), ("Cancel", self.cancel_jobs),
                           ("Screenshot", self.export_screenshot)):
            action = QAction(text, self)
            action.triggered.connect(slot)
            toolbar.addAction(action)

    def _action(self, text: str, slot, shortcut: str | None = None) -> QAction:
        """A menu action; its shortcut works in the whole window (also while a 3D view has the focus)."""
        action = QAction(text, self)
        action.triggered.connect(slot)
        if shortcut:
            action.setShortcut(QKeySequence(shortcut))
            action.setShortcutContext(Qt.WindowShortcut)
        self.addAction(action)
        return action

    def _build_view_menu(self) -> None:
        from PySide6.QtGui import QActionGroup

        from corrlib.viewing import UP_AXES

        view_menu = self.menuBar().addMenu("&View")
        for text, view, shortcut in (("Front", "front", "Ctrl+1"), ("Side", "side", "Ctrl+2"),
                                     ("Top", "top", "Ctrl+3"), ("As drawn (2D-to-3D match)", "drawn", "Ctrl+4"),
                                     ("Reset camera", "reset", "Ctrl+0")):
            view_menu.addAction(self._action(text, lambda _=False, v=view: self.show_view(v), shortcut))
        up_menu = view_menu.addMenu("Up axis")
        self.up_actions = QActionGroup(self)
        for up in UP_AXES:
            action = QAction("auto (the side the shape stands on)" if up == "auto" else up, self)
            action.setCheckable(True)
            action.setChecked(up == "auto")
            action.setData(up)
            action.triggered.connect(lambda _=False, u=up: self.set_up_axis(u))
            self.up_actions.addAction(action)
            up_menu.addAction(action)
        view_menu.addSeparator()
        view_menu.addAction(self._action("Save camera…", self.save_camera_dialog))
        view_menu.addAction(self._action("Load camera…", self.load_camera_dialog))
        view_menu.addSeparator()
        view_menu.addAction(self._action("Next tab", lambda: self._step_tab(1), "Ctrl+PgDown"))
        view_menu.addAction(self._action("Previous tab", lambda: self._step_tab(-1), "Ctrl+PgUp"))

    def _step_tab(self, step: int) -> None:
        self.tabs.setCurrentIndex((self.tabs.currentIndex() + step) % self.tabs.count())

    def framed_views(self) -> list:
        """The views with a camera and an up axis (View menu)."""
        return [self.pair_view, self.compare_view, self.sequence_view, self.product_view]

    def current_framed_view(self):
        view = self.tabs.currentWidget()
        return view if view in self.framed_views() else None

    def show_view(self, view: str) -> None:
        """Camera preset (front, side, top, drawn) in the current tab; ``"reset"``: the tab's default view."""
        target = self.current_framed_view()
        if target is None:
            self.statusBar().showMessage("this tab has no 3D camera")
            return
        target.show_view(target.default_view if view == "reset" else view)

    def set_up_axis(self, up: str) -> None:
        """The up axis of every 3D view (``"auto"`` or ``"+x"`` … ``"-z"``)."""
        for action in self.up_actions.actions():
            action.setChecked(action.data() == up)
        for view in self.framed_views():
            view.set_up_axis(up)
        self.retrieval_view.up = up  # the next ranking's thumbnails
        self.statusBar().showMessage(f"up axis: {up}")

    def save_camera_dialog(self) -> None:
        path = self._save_path("Save camera", "Camera (*.json)")
        if path:
            self.save_camera(path)

    def save_camera(self, path: str) -> None:
        view = self.current_framed_view()
        camera = None if view is None else view.camera()
        if camera is None:
            self.show_error("nothing is shown in this tab: there is no camera to save")
            return
        try:
            camera.save(path)
        except CorrError as exc:
            self.show_error(str(exc))

    def load_camera_dialog(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Load camera", "", "Camera (*.json)")
        if path:
            self.load_camera(path)

    def load_camera(self, path: str) -> None:
        from corrlib.viewing import Camera

        view = self.current_framed_view()
        if view is None:
            self.show_error("this tab has no 3D camera")
            return
        try:
            view.set_camera(Camera.load(path))
        except CorrError as exc:
            self.show_error(str(exc))

    def shortcut_list(self) -> list[tuple[str, str]]:
        """(action, shortcut) of every action with a shortcut (Help ▸ Keyboard shortcuts)."""
        rows = []
        for action in self.findChildren(QAction):
            if not action.shortcut().isEmpty() and action.text():
                rows.append((action.text().replace("&", ""), action.shortcut().toString(QKeySequence.NativeText)))
        return sorted(set(rows), key=lambda r: r[0])

    def show_shortcuts(self) -> None:
        rows = "".join(f"<tr><td>{name}</td><td><b>{keys}</b></td></tr>" for name, keys in self.shortcut_list())
        text = (f"<table>{rows}</table><p>In a 3D view: drag to rotate, shift-drag to pan, wheel to zoom; "
                "click a shape in Compare to inspect a vertex.</p>")
        if self.interactive:
            QMessageBox.information(self, "Keyboard shortcuts", text)
        else:
            self.job_panel.write(text)

    # ------------------------------------------------------------------ messages

    def show_error(self, message: str) -> None:
        self.job_panel.write(f"error: {message}")
        self.statusBar().showMessage(message.splitlines()[0])
        self.error_shown.emit(message)
        if self.interactive:
            QMessageBox.critical(self, "corr studio", message)

    def show_about(self) -> None:
        import numpy
        import PySide6
        import pyvista
        import scipy

        from corrlib.resources import resource

        provenance = resource("README.md").read_text(encoding="utf-8")
        QMessageBox.about(self, "About corr studio",
                          f"<b>corr studio</b> {corrlib.__version__}<br>"
                          f"Continuous non-rigid shape correspondence (Lähner's thesis methods).<br><br>"
                          f"numpy {numpy.__version__}, scipy {scipy.__version__}, pyvista {pyvista.__version__}, "
                          f"PySide6 {PySide6.__version__}<br><br><pre style='font-size:8pt'>"
                          f"{provenance[:ABOUT_PROVENANCE_CHARS]}</pre>")

    # ------------------------------------------------------------------ loading

    def open_dialog(self, which: str) -> None:
        path, _ = QFileDialog.getOpenFileName(self, f"Open {which}", "", f"{MESH_FILTER};;{CONTOUR_FILTER}")
        if path:
            self.load_file(path, which)

    def repair_dialog(self) -> None:
        """A mesh the loader refuses (loose parts, repeated or flat faces, split seams): repaired into a new file
        beside it, then opened as the source, or as the target where a source is open."""
        path, _ = QFileDialog.getOpenFileName(self, "Mesh to repair", "", MESH_FILTER)
        if not path:
            return
        suggested = str(Path(path).with_name(Path(path).stem + ".repaired.off"))
        out, _ = QFileDialog.getSaveFileName(self, "Save the repaired mesh as", suggested, MESH_FILTER)
        if out:
            self.repair_and_load(path, out, "target" if self.source is not None else "source")

    def repair_and_load(self, path: str, out: str, which: str = "source") -> None:
        """Repair the mesh ``path`` into ``out`` (:func:`app.jobs.repair_job`) and use it as ``which``; queued
        with the other loads, a failure shown as an error."""
        self.load_file(out, which, job=repair_job(path, out))

    def open_contour_dialog(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Open contour or silhouette", "", CONTOUR_FILTER)
        if path:
            self.load_file(path, "source")

    def open_gt_dialog(self) -> None:
        a, _ = QFileDialog.getOpenFileName(self, "Ground truth of the source (.vts)", "", dialog_filter("ground-truth"))
        if not a:
            return
        b, _ = QFileDialog.getOpenFileName(self, "Ground truth of the target (.vts)", "", dialog_filter("ground-truth"))
        if b:
            self.load_ground_truth(a, b)

    def load_ground_truth(self, source_vts, target_vts) -> None:
        """Ground truth from two ``.vts`` files (File menu); a bad pair is shown as an error."""
        try:
            self._set_ground_truth(source_vts, target_vts)
        except CorrError as exc:
            self.show_error(str(exc))

    def _set_ground_truth(self, source_vts, target_vts) -> None:
        """Read and use a ground-truth pair (and ``<target>.sym.vts`` beside it); raises CorrError, naming the
        file, where the pair does not fit the loaded meshes."""
        from corrlib.io import load_vts

        if not (isinstance(self.source, TriMesh) and isinstance(self.target, TriMesh)):
            raise CorrError("load a source and a target mesh before their ground truth")
        gt = (load_vts(source_vts, self.source.n_vertices), load_vts(target_vts, self.target.n_vertices))
        if gt[0].shape != gt[1].shape:
            raise CorrError(f"{Path(source_vts).name} has {gt[0].size} rows and {Path(target_vts).name} "
                            f"{gt[1].size}; the rows of a ground-truth pair correspond one to one")
        # the target's mirrored rows, where they lie next to its rows (<name>.sym.vts, as in corr bench)
        sym_path = Path(target_vts).with_name(Path(target_vts).stem + ".sym.vts")
        sym = load_vts(sym_path, self.target.n_vertices) if sym_path.is_file() else None
        if sym is not None and sym.shape != gt[1].shape:
            raise CorrError(f"{sym_path} has {sym.size} rows, {target_vts} {gt[1].size}")
        self.gt = gt + (sym,)
        self.job_panel.write(f"ground truth: {gt[0].size} rows" +
                             (f", mirrored rows from {sym_path.name}" if sym is not None else ""))

    def _ground_truth_beside_files(self) -> None:
        """Load the pair's ground truth where both meshes came from files with ``<name>.vts`` beside them (the
        layout ``corr bench`` reads; ``<target>.sym.vts`` adds the mirrored rows), so that the errors are
        measured without a trip to the File menu. Unusable files are reported in the log, not in a dialog."""
        paths = [self.shape_paths.get(which) for which in ("source", "target")]
        if not (isinstance(self.source, TriMesh) and isinstance(self.target, TriMesh)) or None in paths:
            return
        rows = [path.with_suffix(".vts") for path in paths]
        if paths[0] == paths[1] or not all(row.is_file() for row in rows):
            return
        self.job_panel.write(f"ground truth found beside the meshes: {rows[0].name}, {rows[1].name}")
        try:
            self._set_ground_truth(rows[0], rows[1])
        except CorrError as exc:
            self.job_panel.write(f"ground truth beside the meshes not used: {exc}")

    def load_file(self, path: str, which: str = "source", then: Callable[[], None] | None = None, job=None) -> None:
        """Load a mesh or contour as source/target in the worker (queued: files load one after another).

        Bad files produce a message, never a crash. ``then`` is called on the GUI
        thread once this file is loaded and set (not if loading fails or is cancelled).
        ``job``: the job factory that produces the :class:`~app.jobs.LoadedShape` (default: :func:`load_job`).
        """
        self._load_queue.append((str(path), which, then, job))
        if self._loading is None:
            self._next_load()

    def is_loading(self) -> bool:
        """True while a file is being loaded or waits in the load queue."""
        return self._loading is not None or bool(self._load_queue)

    def _next_load(self) -> None:
        self._loading = self._load_queue.pop(0) if self._load_queue else None
        if self._loading is None:
            self.loading_finished.emit()
            return
        path, which, _then, job = self._loading
        # a running method goes on: set_shape cancels it once a shape is replaced (a load can fail)
        self.job_panel.started(f"loading {which}: {Path(path).name}")
        self.runner.start(LOAD_KEY, load_job(path, as_query=which == "source") if job is None else job)

    def _on_loaded(self, loaded: LoadedShape) -> None:
        _path, which, then, _job = self._loading
        self._job_stopped(f"loaded {loaded.shape.name}")
        if isinstance(loaded.shape, Contour2D) and which == "source":  # the query; a target contour is not one
            self.sketch.show_contour(loaded.shape)
            self.retrieval_view.set_query(loaded.shape)
        self.set_shape(loaded.shape, which, loaded.description, path=loaded.path)
        self._add_recent(loaded.path)
        self._ground_truth_beside_files()
        if then is not None:
            then()
        self._next_load()

    def set_shape(self, shape, which: str, description: str | None = None, path=None) -> None:
        """Use ``shape`` as source/target (``description``: from :func:`app.jobs.describe`, computed if None;
        ``path``: the file it was loaded from, if any).

        Method jobs on the previous pair are cancelled: their results would not fit the new pair.
        """
        self._cancel_method_jobs()
        text = describe(shape) if description is None else description
        self.shape_paths[which] = None if path is None else Path(path)
        label = self.source_info if which == "source" else self.target_info
        label.setText(shortened_words(text))
        label.setToolTip(text)  # the whole names
        if which == "source":
            self.source = shape
        else:
            self.target = shape
        self.gt = None
        self.last_result = None
        self.map_files = []
        self.sequence_view.clear()  # the last pair's motion: its frames would mix two shapes on export
        self.product_view.clear()  # and its match or torus, and its comparison
        if self.compare_view.has_results():
            self.compare_view.clear_results()
        self.pair_view.set_shapes(self.source, self.target)  # a mesh is shown at once, alone until the other comes
        self.refresh_methods()
        self.statusBar().showMessage(self.next_step())  # and no earlier error stays

    def try_retrieval(self) -> None:
        """The Retrieval tab with the bundled collection (10 meshes, 4 classes) and a drawn person as the query."""
        from corrlib.io import load_contour
        from corrlib.resources import RETRIEVAL_QUERY, resource, retrieval_collection

        try:
            folder = retrieval_collection()
            query = load_contour(resource(RETRIEVAL_QUERY))
        except (CorrError, OSError) as exc:
            self.show_error(f"the bundled retrieval collection: {exc}")
            return
        self.retrieval_view.set_folder(str(folder))
        self.retrieval_view.set_query(query)
        self.tabs.setCurrentWidget(self.retrieval_view)
        self.statusBar().showMessage("Retrieval: a drawn person against cats, wolves, a lion and people; press Rank "
                                     "(or draw your own query in the Sketch panel and press Use).")

    def load_demo(self) -> None:
        """Load the bundled pair (the target after the source loaded) with its identity ground truth."""
        from corrlib.resources import DEMO_PAIR, resource

        def identity_ground_truth() -> None:
            if isinstance(self.source, TriMesh) and isinstance(self.target, TriMesh) and \
                    self.source.n_vertices == self.target.n_vertices:
                ident = np.arange(self.source.n_vertices)
                self.gt = (ident, ident)  # the demo pair shares its vertex order
                self.job_panel.write("demo pair loaded (identity ground truth)")

        self.load_file(str(resource(DEMO_PAIR[0])), "source",
                       then=lambda: self.load_file(str(resource(DEMO_PAIR[1])), "target", then=identity_ground_truth))

    def load_bundled(self, which: str) -> None:
        from corrlib.resources import resource

        rel = self.bundled.currentData()
        if rel:
            self.load_file(str(resource(rel)), which)

    def use_sketch(self, contour) -> None:
        self.set_shape(contour, "source")
        self.retrieval_view.set_query(contour)

    def _add_recent(self, path: str) -> None:
        recent = [p for p in (self.settings.value("recent", []) or []) if p != path]
        self.settings.setValue("recent", ([path] + recent)[:MAX_RECENT_FILES])
        self._fill_recent()

    def _fill_recent(self) -> None:
        self.recent_menu.clear()
        for path in self.settings.value("recent", []) or []:
            action = QAction(path, self)
            action.triggered.connect(lambda _=False, p=path: self.load_file(p, self._free_slot()))
            self.recent_menu.addAction(action)

    def dragEnterEvent(self, event):
        if event.mimeData().hasUrls():
            event.acceptProposedAction()

    def dropEvent(self, event):
        for url in event.mimeData().urls():
            path = url.toLocalFile()
            which = "source" if Path(path).suffix.lower() in CONTOUR_SUFFIXES else self._free_slot()
            self.load_file(path, which)

    def _free_slot(self) -> str:
        """"source" while there is no source (loaded or being loaded), else "target"."""
        pending = [entry[1] for entry in ([self._loading] if self._loading else []) + self._load_queue]
        return "source" if self.source is None and "source" not in pending else "target"

    # ------------------------------------------------------------------ methods and jobs

    def refresh_methods(self) -> None:
        current = self.method_box.currentData()
        self.method_box.blockSignals(True)
        self.method_box.clear()
        specs = methods_for(self.source, self.target) if self.source is not None and self.target is not None else []
        for spec in specs:
            self.method_box.addItem(spec.label, spec.name)
        index = self.method_box.findData(current)
        self.method_box.setCurrentIndex(index if index >= 0 else 0)
        self.method_box.blockSignals(False)
        self._on_method_changed()
        self.compare_view.set_methods(specs if all(isinstance(s, TriMesh) for s in (self.source, self.target)) else [])
        self.run_button.setEnabled(bool(specs))

    def _on_method_changed(self, *_args) -> None:
        name = self.method_box.currentData()
        self.forms.setVisible(name is not None)
        if name is None:
            self.method_desc.setText("Load two compatible inputs to see the methods that accept them.")
            return
        from corrlib.methods import get_method

        spec = get_method(name)
        self.method_desc.setText(spec.description)
        # the stack takes the height of the shown form only, so that Run follows it (not the longest form)
        for form in self._forms.values():
            policy = QSizePolicy.Preferred if form is self._forms[name] else QSizePolicy.Ignored
            form.setSizePolicy(policy, policy)
        self.forms.setCurrentWidget(self._forms[name])
        self.forms.adjustSize()

    def form_of(self, method: str) -> ParamForm | None:
        """The parameter form of the registered method ``method`` (None for an unknown name)."""
        return self._forms.get(method)

    def current_params(self, name: str):
        return self._forms[name].params()

    def next_step(self) -> str:
        """What the user can do with the inputs loaded (the status bar after each load, and why Run cannot)."""
        if self.source is None or self.target is None:
            return (f"Load a {'target' if self.source is not None else 'source'} (File menu, drag and drop) or "
                    "open the demo pair.")
        if self.method_box.count():
            return "Pick a method and press Run."
        if isinstance(self.source, TriMesh) and isinstance(self.target, Contour2D):
            return ("No method matches a mesh to a contour: a 2D-to-3D match takes the contour as the source and "
                    "the mesh as the target.")
        return "No method takes these two inputs."

    def run_method(self, *_args, method: str | None = None) -> None:
        if method is not None and self.method_box.findData(method) >= 0:
            self.method_box.setCurrentIndex(self.method_box.findData(method))  # the form shows what runs
        name = method or self.method_box.currentData()
        if name is None:
            step = self.next_step()
            self.show_error(f"no method to run: {step[0].lower()}{step[1:]}")
            return
        if name not in self._forms:  # every registered method has a form
            self.show_error(f"unknown method {name!r} (available: {', '.join(sorted(self._forms))})")
            return
        self._start_method(PAIR_KEY, name)

    def _start_method(self, key: str, name: str) -> bool:
        """Validate the form of ``name`` and start it on the loaded pair as job ``key``.

        The job also measures the map's errors against the loaded ground truth
        and, for the pair view, computes the source function (:func:`app.jobs.method_job`).
        """
        try:
            params = self.current_params(name)
        except CorrError as exc:
            self.show_error(f"{name}: invalid parameters: {exc}")
            return False
        self.job_panel.started(f"{'compare: ' if key == COMPARE_KEY else ''}running {name}")
        self.runner.start(key, method_job(name, self.source, self.target, params, self.gt,
                                          view_data=key == PAIR_KEY))
        return True

    def _cancel_method_jobs(self) -> None:
        for key in (PAIR_KEY, COMPARE_KEY):
            self.runner.cancel(key)
        self._compare_queue.clear()

    def cancel_jobs(self) -> None:
        """Cancel every running job and forget the files waiting to be loaded."""
        self._load_queue.clear()
        for key in (LOAD_KEY, PAIR_KEY, RETRIEVAL_KEY, COMPARE_KEY):
            self.runner.cancel(key)
        self._compare_queue.clear()

    def _on_progress(self, key: str, report) -> None:
        self.job_panel.report(report)

    def _job_stopped(self, text: str, finished: bool = True) -> None:
        """The job panel told that a job ended, and which go on (the panel is shared by every kind of job); a
        finished job's word also replaces the status bar's hint, which asked for the run just made."""
        if finished:
            self.statusBar().showMessage(text)
        self.job_panel.stopped(text, tuple(name for key, name in JOB_NAMES.items() if self.runner.is_running(key)),
                               finished)

    def _on_failed(self, key: str, message: str) -> None:
        self._job_stopped("failed", finished=False)
        if key == COMPARE_KEY:  # one method failing leaves the others of the comparison to run
            self.show_error(f"{self._compare_current}: {message}")
            self._next_compare()
            return
        if key != LOAD_KEY:
            self._compare_queue.clear()
        elif REPAIR_ADVICE in message:  # the studio's way to the same repair
            message += "\n\nIn the studio: File ▸ Repair and open a mesh…"
        self.show_error(message)
        if key == LOAD_KEY:
            self._next_load()

    def _on_cancelled(self, key: str) -> None:
        self._job_stopped("cancelled", finished=False)
        if key == LOAD_KEY:
            self._next_load()
        else:
            self._compare_queue.clear()

    def _on_finished(self, key: str, payload) -> None:
        if key == LOAD_KEY:
            self._on_loaded(payload)
            return
        if key == RETRIEVAL_KEY:
            hits, meshes = payload
            self.retrieval_view.show_results(hits, meshes)
            failed = [hit for hit in hits if hit.error]
            for hit in failed:  # the gallery shows why on hover only
                said = hit.error.removeprefix(str(hit.path)).removeprefix(hit.name).removeprefix(": ")
                said = f"{hit.name}: {said}"  # once, the file's name in the collection
                self.job_panel.write(f"not ranked: {said}")
            ranked = len(hits) - len(failed)
            self._job_stopped(f"ranked {ranked} mesh{'es' if ranked != 1 else ''}" +
                              (f"; {len(failed)} could not be matched (see the log)" if failed else ""))
            self.result_ready.emit(hits)
            return
        outcome: MethodOutcome = payload
        result = outcome.result
        self._job_stopped(f"{result.method} finished")
        if outcome.source is not self.source or outcome.target is not self.target:
            self.job_panel.write(f"{result.method}: result dropped, the inputs changed while it ran")
            return
        self._log_outcome(outcome)
        if key == COMPARE_KEY:
            self.compare_view.add_result(self.source, self.target, result, outcome.report, outcome.n_unmatched,
                                         None if outcome.errors is None else outcome.errors.per_vertex)
            self._next_compare()
            if not self.runner.is_running(COMPARE_KEY):
                self.result_ready.emit(result)
            return
        self.last_result = result
        if outcome.map_file is not None and outcome.map_file not in self.map_files:
            self.map_files.append(outcome.map_file)
        if isinstance(self.source, Contour2D) and isinstance(self.target, Contour2D):
            self.tabs.setCurrentWidget(self.product_view)
            self.product_view.show_contour_pair(result)
        elif isinstance(self.source, Contour2D):
            self.tabs.setCurrentWidget(self.product_view)  # shown first, so the cameras fit its real size
            path = result.path
            self.product_view.show_contour_match(path.contour_points, self.target, path.vertices,
                                                 path.contour_index, result.energy)
            self.job_panel.write(contour_reading(result))
        else:
            self.tabs.setCurrentWidget(self.pair_view)
            self.pair_view.set_result(result, None if outcome.errors is None else outcome.errors.per_vertex,
                                      function=outcome.function, n_unmatched=outcome.n_unmatched)
            if outcome.sequences:
                self.sequence_view.set_sequences(self.source, outcome.sequences, self.target)
            from corrlib.methods.kernel_matching import (  # loaded by the method that ran
                copies_note, reversal_note, start_note, turn_note)

            from corrlib.evaluation import collapse_note

            for note in (copies_note(result.extras), reversal_note(result.extras), turn_note(result.extras),
                         start_note(result.extras),
                         collapse_note(result.map_xy, self.source, self.target)):
                if note:
                    self.job_panel.write(f"{result.method}: {note}")
        self.result_ready.emit(result)

    def _log_outcome(self, outcome: MethodOutcome) -> None:
        """Write the error summary (computed in the job) and the unmatched count to the job log."""
        name = outcome.result.method
        if outcome.note:
            self.job_panel.write(f"{name}: {outcome.note}")
        if outcome.n_unmatched:
            self.job_panel.write(f"{name}: {outcome.n_unmatched} source vertices unmatched")
        errors = outcome.errors
        if errors is None:
            return
        left_out = f" ({errors.n_unmatched} of {errors.n_rows} rows unmatched, left out)" if errors.n_unmatched else ""
        if errors.report is None:
            self.job_panel.write(f"error: no ground-truth row is matched{left_out}")
        else:
            self.job_panel.write("error: " + ", ".join(f"{k} {v:.3f}" for k, v in errors.report.summary().items())
                                 + left_out)

    def run_retrieval(self) -> None:
        view = self.retrieval_view
        if view.query is None or view.folder is None:
            self.show_error("retrieval needs a query (sketch or silhouette) and a folder of meshes")
            return
        view.clear_results()
        self.job_panel.started(f"ranking {view.folder}")
        self.runner.start(RETRIEVAL_KEY, retrieval_job(view.query, view.folder, ranking=view.ranking.currentText()))

    def open_retrieved_pair(self, query, mesh_path: str) -> None:
        """The query as source, ``mesh_path`` as target (loaded in the worker), then the 2D-to-3D match."""
        self.set_shape(query, "source")
        self.load_file(mesh_path, "target", then=lambda: self.run_method(method="contour3d"))

    def run_compare(self) -> None:
        if not (isinstance(self.source, TriMesh) and isinstance(self.target, TriMesh)):
            self.show_error("the comparison needs a source and a target mesh")
            return
        self._compare_queue = [("method", m) for m in self.compare_view.selected()] + [("map", f) for f in
                                                                                        self.map_files]
        if not self._compare_queue:
            self.show_error("select at least one method to compare (or open a map of this pair)")
            return
        self.tabs.setCurrentWidget(self.compare_view)
        self.compare_view.clear_results(len(self._compare_queue))
        self.compare_view.set_ground_truth(*(self.gt[:2] if self.gt is not None else (None, None)),
                                           self.source.n_vertices)
        self._next_compare()

    def _next_compare(self) -> None:
        """Start the next method of the comparison; one whose parameters are invalid is skipped (it said why)."""
        while self._compare_queue:
            kind, self._compare_current = self._compare_queue.pop(0)
            if kind == "map":
                self.runner.start(COMPARE_KEY, map_job(self._compare_current, self.source, self.target, self.gt,
                                                       view_data=False))
                return
            if self._start_method(COMPARE_KEY, self._compare_current):
                return

    # ------------------------------------------------------------------ exports (atomic, ask before overwrite)

    def _save_path(self, title: str, filt: str) -> str | None:
        path, _ = QFileDialog.getSaveFileName(self, title, "", filt)  # the dialog asks before overwriting
        return path or None

    def export_map(self, kind: str) -> None:
        from corrlib.io import save_map

        if self.last_result is None or self.last_result.map_xy is None:
            self.show_error("run a method first: there is no map to export")
            return
        path = self._save_path("Export map", dialog_filter("map" if kind == "txt" else "result", save=True))
        if path:
            try:
                save_map(path, self.last_result.map_xy) if kind == "txt" else self.last_result.save(path)
            except (CorrError, OSError) as exc:
                self.show_error(str(exc))

    def export_colored(self) -> None:
        from corrlib.io import save_mesh

        colors = self.pair_view.target_colors
        if colors is None:
            self.show_error("no coloured target to export (run a method, show 'coordinates')")
            return
        path = self._save_path("Export coloured target", dialog_filter("mesh", save=True))
        if path:
            try:
                save_mesh(path, self.target.vertices, self.target.faces, colors)
            except (CorrError, OSError) as exc:
                self.show_error(str(exc))

    def open_map_dialog(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Map of the loaded pair", "", dialog_filter("map", "result"))
        if path:
            self.load_map(path)

    def load_map(self, path: str) -> None:
        """Show a map from a file (another tool's, an earlier run's) as a method's result: pair view, errors
        against the loaded ground truth, sequence (:func:`app.jobs.map_job`)."""
        if not (isinstance(self.source, TriMesh) and isinstance(self.target, TriMesh)):
            self.show_error("a map needs two meshes: " + self.next_step().lower())
            return
        self.job_panel.started(f"reading the map {Path(path).name}")
        self.runner.start(PAIR_KEY, map_job(path, self.source, self.target, self.gt))

    def open_texture_dialog(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Texture image", "", dialog_filter("texture"))
        if path:
            self.load_texture(path)

    def load_texture(self, path: str) -> None:
        from PIL import Image, UnidentifiedImageError

        from corrlib.io import check_image_size

        try:
            with Image.open(path) as im:
                check_image_size(path, *im.size)
                self.pair_view.texture_image = np.asarray(im.convert("RGB"))
        except CorrError as exc:
            self.show_error(str(exc))
            return
        except (OSError, UnidentifiedImageError, Image.DecompressionBombError, ValueError, SyntaxError) as exc:
            self.show_error(f"{path}: cannot read the texture image: {exc}")
            return
        self.pair_view.mode.setCurrentText("texture")
        self.pair_view.redraw()

    def export_frames(self, suffix: str = ".obj", folder: str | None = None) -> list[Path]:
        """Write :data:`N_EXPORT_FRAMES` frames from t = 0 to t max with the source's connectivity,
        ``animation.glb`` (glTF morph-target animation) and ``volumes.csv`` (asks before overwriting)."""
        from corrlib.morph import export_sequence, largest_volume_change, last_frame_note

        if self.sequence_view.positions is None:
            self.show_error("no sequence to export (run a method on two meshes)")
            return []
        folder = folder or QFileDialog.getExistingDirectory(self, "Folder for the frames")
        if not folder:
            return []
        times, frames = map(list, zip(*self.sequence_view.frames(N_EXPORT_FRAMES)))
        existing = [p for p in Path(folder).glob("frame_*") if p.suffix == suffix] + \
            [p for p in (Path(folder) / "animation.glb",) if p.exists()]
        if existing and self.interactive and QMessageBox.question(
                self, "corr studio", f"{len(existing)} frame files exist in {folder}. Overwrite them?") \
                != QMessageBox.Yes:
            return []
        try:
            mesh, motion = self.sequence_view.source, self.sequence_view.motion.currentData()  # what moves, how
            written = export_sequence(folder, frames, mesh.faces, times, fmt=suffix.lstrip("."), closed=mesh.is_closed)
        except (CorrError, OSError) as exc:
            self.show_error(str(exc))
            return []
        change = largest_volume_change(written["volume"], mesh.area)
        note = (f"largest volume change {change:.2e}" if change is not None
                else "volume does not apply (open mesh, or a closed one that encloses none)")
        folds = last_frame_note(self.last_result, mesh, self.target, times, frames, motion)
        self.job_panel.write(f"wrote {len(frames)} frames, animation.glb and volumes.csv to {folder} ({note}"
                             f"{'' if folds is None else '; ' + folds})")
        return written["frames"]

    def export_strip(self) -> None:
        from PIL import Image

        from corrlib.io import atomic_write

        if self.sequence_view.positions is None:
            self.show_error("no sequence to export (run a method on two meshes)")
            return
        path = self._save_path("Sequence picture strip", dialog_filter("picture", save=True))
        if path:
            self.tabs.setCurrentWidget(self.sequence_view)
            strip = self.sequence_view.picture_strip()
            try:
                with atomic_write(path, "wb") as fh:
                    Image.fromarray(strip).save(fh, format="PNG")
            except (CorrError, OSError) as exc:
                self.show_error(str(exc))

    def export_screenshot(self) -> None:
        path = self._save_path("Screenshot", dialog_filter("picture", save=True))
        if path:
            try:
                self.save_screenshot(path)
            except (CorrError, OSError) as exc:
                self.show_error(str(exc))

    def save_screenshot(self, path: str) -> None:
        """The window as the screen shows it (OpenGL views included), written atomically."""
        from corrlib.io import atomic_write

        pixmap = self.screen().grabWindow(0, self.x(), self.y(), self.frameGeometry().width(),
                                          self.frameGeometry().height())
        from PySide6.QtCore import QBuffer, QByteArray, QIODevice

        data = QByteArray()
        buffer = QBuffer(data)
        buffer.open(QIODevice.WriteOnly)
        pixmap.save(buffer, "PNG")
        with atomic_write(path, "wb") as fh:
            fh.write(bytes(data))

    def export_transparent(self) -> None:
        path = self._save_path("3D view with a transparent background", dialog_filter("picture", save=True))
        if path:
            self.save_transparent(path)

    def save_transparent(self, path: str) -> None:
        """The current tab's 3D view (every subplot) as a PNG with a transparent background."""
        view = self.current_framed_view()
        plotter = None if view is None else view.view_plotter()
        if plotter is None or not view.framed_points():
            self.show_error("this tab shows no 3D view to save")
            return
        self._save_plotter_picture(plotter, path, transparent=True)

    def export_compare_grid(self) -> None:
        if not self.compare_view.has_results():
            self.show_error("run a comparison first: the compare grid is empty")
            return
        path = self._save_path("Compare grid", dialog_filter("picture", save=True))
        if path:
            self.save_compare_grid(path)

    def save_compare_grid(self, path: str) -> None:
        """Every view of the compare grid, with its captions, as one picture."""
        if not self.compare_view.has_results():
            self.show_error("run a comparison first: the compare grid is empty")
            return
        self._save_plotter_picture(self.compare_view.plotter, path, transparent=False)

    def _save_plotter_picture(self, plotter, path: str, transparent: bool) -> None:
        from PIL import Image

        from corrlib.io import atomic_write, check_output_file

        try:
            check_output_file(path, "picture")
            image = plotter.screenshot(transparent_background=transparent, return_img=True)
            with atomic_write(path, "wb") as fh:
                Image.fromarray(image).save(fh, format="PNG")
        except CorrError as exc:
            self.show_error(str(exc))
            return
        self.statusBar().showMessage(f"saved {path}")

    def export_table(self) -> None:
        from corrlib.io import atomic_write

        rows = self.compare_view.table_rows()
        if not rows:
            self.show_error("the comparison table is empty")
            return
        path = self._save_path("Comparison table", dialog_filter("table", save=True))
        if path:
            buf = io.StringIO()
            writer = csv.writer(buf)
            writer.writerow([self.compare_view.table.horizontalHeaderItem(c).text()
                             for c in range(self.compare_view.table.columnCount())])
            writer.writerows(rows)
            with atomic_write(path) as fh:
                fh.write(buf.getvalue())

    # ------------------------------------------------------------------ closing

    def closeEvent(self, event):
        self.settings.setValue("window/state", self.saveState())
        self.settings.setValue("window/geometry", self.saveGeometry())
        self.settings.sync()  # on disk now, whatever happens at exit
        self._closed = True
        self.runner.shutdown()
        if self._warm_up_thread is not None:  # no studio thread may outlive the window (see app.gui_gc)
            self._warm_up_thread.join(SHUTDOWN_TIMEOUT_S)
        was_loading = self.is_loading()
        self._load_queue.clear()
        self._loading = None
        if was_loading:
            self.loading_finished.emit()  # nothing more will load: release whoever waits for the loads
        for view in (self.pair_view, self.product_view, self.sequence_view, self.retrieval_view, self.compare_view):
            view.close_plotters()
        self._collector.release(self)
        super().closeEvent(event)

