"""The studio's main window: docks (shapes, sketch, method, job), views (tabs), menus, exports."""

from __future__ import annotations

import csv
import io
import time
from pathlib import Path

import numpy as np
from PySide6.QtCore import QSettings, Qt, QTimer, Signal
from PySide6.QtGui import QAction, QKeySequence
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
    QStackedWidget,
    QTabWidget,
    QVBoxLayout,
    QWidget,
)

import corrlib
from app.param_form import ParamForm
from app.sketch import SketchPanel
from app.views.compare import CompareView
from app.views.pair import PairView
from app.views.product import ProductView
from app.views.retrieval import RetrievalView, retrieval_job
from app.views.sequence import SequenceView
from app.worker import JobRunner, progress_text
from corrlib.errors import CorrError
from corrlib.io import IMAGE_SUFFIXES, MESH_SUFFIXES, POINT_SUFFIXES, load_contour, load_mesh
from corrlib.methods import all_methods, methods_for, solve_iter
from corrlib.shapes import Contour2D, TriMesh

CONTOUR_SUFFIXES = IMAGE_SUFFIXES | POINT_SUFFIXES | {".svg"}
MESH_FILTER = "Meshes (*.off *.obj *.ply *.stl)"
CONTOUR_FILTER = "Contours and silhouettes (*.png *.gif *.jpg *.jpeg *.bmp *.tif *.tiff *.svg *.txt *.csv *.xy *.pts *.dat)"


def describe(shape) -> str:
    if isinstance(shape, TriMesh):
        warnings = [f.message for f in shape.report() if f.level == "warning"]
        text = f"{shape.name}: {shape.n_vertices} vertices, {shape.n_faces} faces, area {shape.area:.4g}"
        return text + ("\n  " + "\n  ".join(warnings) if warnings else "\n  validation: no problems")
    if isinstance(shape, Contour2D):
        return f"{shape.name}: contour, {shape.n_points} points, length {shape.length:.4g}"
    return "none"


class JobPanel(QWidget):
    """Progress bar, stage text, elapsed time, cancel button, log; measures GUI stalls during jobs."""

    cancel_requested = Signal()

    def __init__(self, parent=None):
        super().__init__(parent)
        self.bar = QProgressBar()
        self.bar.setRange(0, 1000)
        self.stage = QLabel("idle")
        self.stage.setWordWrap(True)
        self.elapsed = QLabel("")
        self.cancel = QPushButton("Cancel")
        self.cancel.setEnabled(False)
        self.cancel.clicked.connect(self.cancel_requested)
        self.log = QPlainTextEdit()
        self.log.setReadOnly(True)
        self.log.setMaximumBlockCount(2000)
        layout = QVBoxLayout(self)
        for w in (self.bar, self.stage, self.elapsed, self.cancel):
            layout.addWidget(w)
        layout.addWidget(self.log, 1)
        self._start = None
        self._last_tick = None
        self.max_stall = 0.0  # longest gap between GUI timer ticks while a job ran (seconds)
        self.max_stall_stage = ""  # the stage shown when it happened
        self.timer = QTimer(self)
        self.timer.setInterval(20)
        self.timer.timeout.connect(self._tick)

    def started(self, text: str) -> None:
        self._start = self._last_tick = time.perf_counter()
        self.max_stall = 0.0
        self.max_stall_stage = ""
        self.bar.setRange(0, 1000)
        self.bar.setValue(0)
        self.stage.setText(text)
        self.cancel.setEnabled(True)
        self.timer.start()
        self.write(text)

    def report(self, report) -> None:
        if report.fraction >= 0:
            self.bar.setRange(0, 1000)
            self.bar.setValue(int(1000 * report.fraction))
        else:
            self.bar.setRange(0, 0)  # busy indicator
        self.stage.setText(progress_text(report))
        if report.message:
            self.write(progress_text(report))

    def stopped(self, text: str) -> None:
        self.timer.stop()
        self.bar.setRange(0, 1000)
        self.bar.setValue(1000)
        self.cancel.setEnabled(False)
        took = time.perf_counter() - self._start if self._start else 0.0
        self.stage.setText(text)
        self.write(f"{text} ({took:.2f} s; longest GUI stall {1000 * self.max_stall:.0f} ms)")

    def _tick(self) -> None:
        now = time.perf_counter()
        stall = now - self._last_tick - self.timer.interval() / 1000.0
        if stall > self.max_stall:
            self.max_stall, self.max_stall_stage = stall, self.stage.text()
        self._last_tick = now
        self.elapsed.setText(f"elapsed {now - self._start:.1f} s")

    def write(self, text: str) -> None:
        self.log.appendPlainText(f"[{time.strftime('%H:%M:%S')}] {text}")


class MainWindow(QMainWindow):
    """The studio. ``result_ready`` fires when a pair/contour result is on screen."""

    result_ready = Signal(object)
    error_shown = Signal(str)

    def __init__(self, settings: QSettings | None = None, interactive: bool = True):
        super().__init__()
        self.setWindowTitle("corr studio")
        self.settings = settings or QSettings("corrlib", "corr-studio")
        self.interactive = interactive  # False in tests/screenshots: errors go to the log, not modal dialogs
        self.source = self.target = None
        self.gt: tuple[np.ndarray, np.ndarray] | None = None
        self.last_result = None
        self.runner = JobRunner(self)
        self.runner.progress.connect(self._on_progress)
        self.runner.finished.connect(self._on_finished)
        self.runner.failed.connect(self._on_failed)
        self.runner.cancelled.connect(self._on_cancelled)
        self._compare_queue: list[str] = []

        self.tabs = QTabWidget()
        self.pair_view = PairView()
        self.product_view = ProductView()
        self.sequence_view = SequenceView()
        self.retrieval_view = RetrievalView()
        self.compare_view = CompareView()
        for name, view in (("Pair", self.pair_view), ("Product", self.product_view),
                           ("Sequence", self.sequence_view), ("Retrieval", self.retrieval_view),
                           ("Compare", self.compare_view)):
            self.tabs.addTab(view, name)
        self.setCentralWidget(self.tabs)
        self.retrieval_view.run_requested.connect(self.run_retrieval)
        self.retrieval_view.open_pair.connect(self.open_retrieved_pair)
        self.compare_view.run_button.clicked.connect(self.run_compare)

        self._build_docks()
        self._build_menus()
        self.statusBar().showMessage("Load shapes (File menu, drag and drop) or open the demo pair.")
        self.setAcceptDrops(True)
        self.resize(1500, 950)
        state = self.settings.value("window/state")
        geometry = self.settings.value("window/geometry")
        if geometry is not None:
            self.restoreGeometry(geometry)
        if state is not None:
            self.restoreState(state)
        self.refresh_methods()
        # load the compiled kernels while the window is idle, not during the first solve
        QTimer.singleShot(300, self._warm_up)

    def _warm_up(self) -> None:
        import threading

        from corrlib.warmup import warm_up

        threading.Thread(target=warm_up, name="corr-warm-up", daemon=True).start()

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
        self._form_of: dict[str, ParamForm] = {}
        for spec in all_methods():
            form = ParamForm(spec.params)
            self._form_of[spec.name] = form
            self.forms.addWidget(form)
        self.run_button = QPushButton("Run")
        self.run_button.clicked.connect(self.run_method)
        for w in (self.method_box, self.method_desc, self.forms, self.run_button):
            mlay.addWidget(w)
        self.job_panel = JobPanel()
        self.job_panel.cancel_requested.connect(self.cancel_jobs)
        for title, widget, area in (("Shapes", shapes, Qt.LeftDockWidgetArea),
                                    ("Sketch", self.sketch, Qt.LeftDockWidgetArea),
                                    ("Method", method, Qt.RightDockWidgetArea),
                                    ("Job", self.job_panel, Qt.RightDockWidgetArea)):
            dock = QDockWidget(title, self)
            dock.setObjectName(f"dock-{title}")
            dock.setWidget(widget)
            self.addDockWidget(area, dock)

    def _build_menus(self) -> None:
        file_menu = self.menuBar().addMenu("&File")
        for text, slot, shortcut in (("Open source…", lambda: self.open_dialog("source"), QKeySequence.Open),
                                     ("Open target…", lambda: self.open_dialog("target"), None),
                                     ("Open contour / silhouette…", self.open_contour_dialog, None),
                                     ("Load ground truth (.vts pair)…", self.open_gt_dialog, None),
                                     ("Texture image…", self.open_texture_dialog, None),
                                     ("Demo pair", self.load_demo, None)):
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
                           ("Comparison table (CSV)…", self.export_table)):
            action = QAction(text, self)
            action.triggered.connect(slot)
            export.addAction(action)
        quit_action = QAction("Quit", self)
        quit_action.setShortcut(QKeySequence.Quit)
        quit_action.triggered.connect(self.close)
        file_menu.addAction(quit_action)
        run_menu = self.menuBar().addMenu("&Run")
        for text, slot in (("Run method", self.run_method), ("Cancel", self.cancel_jobs)):
            action = QAction(text, self)
            action.triggered.connect(slot)
            run_menu.addAction(action)
        help_menu = self.menuBar().addMenu("&Help")
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

        provenance = resource("README.md").read_text()
        QMessageBox.about(self, "About corr studio",
                          f"<b>corr studio</b> {corrlib.__version__}<br>"
                          f"Continuous non-rigid shape correspondence (Lähner's thesis methods).<br><br>"
                          f"numpy {numpy.__version__}, scipy {scipy.__version__}, pyvista {pyvista.__version__}, "
                          f"PySide6 {PySide6.__version__}<br><br><pre style='font-size:8pt'>"
                          f"{provenance[:3000]}</pre>")

    # ------------------------------------------------------------------ loading

    def open_dialog(self, which: str) -> None:
        path, _ = QFileDialog.getOpenFileName(self, f"Open {which}", "", f"{MESH_FILTER};;{CONTOUR_FILTER}")
        if path:
            self.load_file(path, which)

    def open_contour_dialog(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Open contour or silhouette", "", CONTOUR_FILTER)
        if path:
            self.load_file(path, "source")

    def open_gt_dialog(self) -> None:
        a, _ = QFileDialog.getOpenFileName(self, "Ground truth of the source (.vts)", "", "*.vts")
        if not a:
            return
        b, _ = QFileDialog.getOpenFileName(self, "Ground truth of the target (.vts)", "", "*.vts")
        if b:
            self.load_ground_truth(a, b)

    def load_ground_truth(self, source_vts, target_vts) -> None:
        from corrlib.io import load_vts

        try:
            if not (isinstance(self.source, TriMesh) and isinstance(self.target, TriMesh)):
                raise CorrError("load a source and a target mesh before their ground truth")
            self.gt = (load_vts(source_vts, self.source.n_vertices), load_vts(target_vts, self.target.n_vertices))
        except CorrError as exc:
            self.show_error(str(exc))
            return
        self.job_panel.write(f"ground truth: {self.gt[0].size} rows")

    def load_file(self, path: str, which: str = "source") -> bool:
        """Load a mesh or contour as source/target; bad files produce a message, never a crash."""
        suffix = Path(path).suffix.lower()
        try:
            shape = load_mesh(path) if suffix in MESH_SUFFIXES else load_contour(path)
        except CorrError as exc:
            self.show_error(str(exc))
            return False
        except Exception as exc:  # anything unexpected from a third-party reader
            self.show_error(f"{path}: cannot load: {exc}")
            return False
        if isinstance(shape, Contour2D):
            self.sketch.show_contour(shape)
            self.retrieval_view.set_query(shape)
        self.set_shape(shape, which)
        self._add_recent(path)
        return True

    def set_shape(self, shape, which: str) -> None:
        if which == "source":
            self.source = shape
            self.source_info.setText(describe(shape))
        else:
            self.target = shape
            self.target_info.setText(describe(shape))
        self.gt = None
        self.last_result = None
        if isinstance(self.source, TriMesh) and isinstance(self.target, TriMesh):
            self.pair_view.set_shapes(self.source, self.target)
        self.refresh_methods()

    def load_demo(self) -> None:
        from corrlib.resources import DEMO_PAIR, resource

        if self.load_file(str(resource(DEMO_PAIR[0])), "source") and \
                self.load_file(str(resource(DEMO_PAIR[1])), "target"):
            ident = np.arange(self.source.n_vertices)
            self.gt = (ident, ident)  # the demo pair shares its vertex order
            self.job_panel.write("demo pair loaded (identity ground truth)")

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
        self.settings.setValue("recent", ([path] + recent)[:10])
        self._fill_recent()

    def _fill_recent(self) -> None:
        self.recent_menu.clear()
        for path in self.settings.value("recent", []) or []:
            action = QAction(path, self)
            action.triggered.connect(lambda _=False, p=path: self.load_file(p, "source" if self.source is None else "target"))
            self.recent_menu.addAction(action)

    def dragEnterEvent(self, event):
        if event.mimeData().hasUrls():
            event.acceptProposedAction()

    def dropEvent(self, event):
        for url in event.mimeData().urls():
            path = url.toLocalFile()
            which = "source" if self.source is None or Path(path).suffix.lower() in CONTOUR_SUFFIXES else "target"
            self.load_file(path, which)

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
        self.forms.setCurrentWidget(self._form_of[name])

    def current_params(self, name: str):
        return self._form_of[name].params()

    def run_method(self, *_args, method: str | None = None) -> None:
        if method is not None and self.method_box.findData(method) >= 0:
            self.method_box.setCurrentIndex(self.method_box.findData(method))  # the form shows what runs
        name = method or self.method_box.currentData()
        if name is None:
            self.show_error("no method accepts the loaded inputs (load a source and a target)")
            return
        self._start_method("pair", name)

    def _start_method(self, key: str, name: str) -> bool:
        """Validate the form of ``name`` and start it on the loaded pair as job ``key``."""
        try:
            params = self.current_params(name)
        except CorrError as exc:
            self.show_error(f"{name}: invalid parameters: {exc}")
            return False
        source, target = self.source, self.target
        self.job_panel.started(f"{'compare: ' if key == 'compare' else ''}running {name}")
        self.runner.start(key, lambda token: solve_iter(name, source, target, params, token))
        return True

    def cancel_jobs(self) -> None:
        for key in ("pair", "retrieval", "compare"):
            self.runner.cancel(key)
        self._compare_queue.clear()

    def _on_progress(self, key: str, report) -> None:
        self.job_panel.report(report)

    def _on_failed(self, key: str, message: str) -> None:
        self.job_panel.stopped("failed")
        self._compare_queue.clear()
        self.show_error(message)

    def _on_cancelled(self, key: str) -> None:
        self.job_panel.stopped("cancelled")
        self._compare_queue.clear()

    def _error_report(self, result):
        from corrlib.evaluation import geodesic_errors

        if self.gt is None or result.map_xy is None or not isinstance(self.target, TriMesh):
            return None
        return geodesic_errors(np.maximum(result.map_xy, 0), self.target, self.gt[0], self.gt[1], method="heat")

    def _on_finished(self, key: str, payload) -> None:
        if key == "retrieval":
            hits, thumbs = payload
            self.retrieval_view.show_results(hits, thumbs)
            self.job_panel.stopped(f"ranked {len(hits)} meshes")
            self.result_ready.emit(hits)
            return
        result = payload
        self.job_panel.stopped(f"{result.method} finished")
        if key == "compare":
            self.compare_view.add_result(self.source, self.target, result, self._error_report(result))
            self._next_compare()
            if not self.runner.is_running("compare"):
                self.result_ready.emit(result)
            return
        self.last_result = result
        if isinstance(self.source, Contour2D) and isinstance(self.target, Contour2D):
            self.tabs.setCurrentWidget(self.product_view)
            self.product_view.show_contour_pair(result)
        elif isinstance(self.source, Contour2D):
            ex = result.extras
            self.tabs.setCurrentWidget(self.product_view)  # shown first, so the cameras fit its real size
            self.product_view.show_contour_match(ex["contour_points"], self.target, ex["path_vertices"],
                                                 ex["path_contour_index"], result.energy)
        else:
            report = self._error_report(result)
            errors = None
            if report is not None:
                errors = np.full(self.source.n_vertices, np.nan)
                errors[self.gt[0]] = report.errors
                self.job_panel.write("error: " + ", ".join(f"{k} {v:.3f}" for k, v in report.summary().items()))
            self.tabs.setCurrentWidget(self.pair_view)
            self.pair_view.set_result(result, errors)
            self._show_sequence(result)
        self.result_ready.emit(result)

    def _show_sequence(self, result) -> None:
        from corrlib.morph import FLOW_DESCRIPTION, LINEAR_DESCRIPTION, has_deformation, sequence_positions

        # up to the largest t the slider allows (a divergence-free result stores its flow that far)
        positions = sequence_positions(result, self.source, self.target, t_max=self.sequence_view.t_max.maximum())
        self.sequence_view.set_sequence(self.source, positions,
                                        FLOW_DESCRIPTION if has_deformation(result) else LINEAR_DESCRIPTION)

    def run_retrieval(self) -> None:
        view = self.retrieval_view
        if view.query is None or view.folder is None:
            self.show_error("retrieval needs a query (sketch or silhouette) and a folder of meshes")
            return
        self.job_panel.started(f"ranking {view.folder}")
        self.runner.start("retrieval", retrieval_job(view.query, view.folder))

    def open_retrieved_pair(self, query, mesh_path: str) -> None:
        self.set_shape(query, "source")
        if self.load_file(mesh_path, "target"):
            self.run_method(method="contour3d")

    def run_compare(self) -> None:
        if not (isinstance(self.source, TriMesh) and isinstance(self.target, TriMesh)):
            self.show_error("the comparison needs a source and a target mesh")
            return
        self._compare_queue = self.compare_view.selected()
        if not self._compare_queue:
            self.show_error("select at least one method to compare")
            return
        self.tabs.setCurrentWidget(self.compare_view)
        self.compare_view.clear_results(len(self._compare_queue))
        self._next_compare()

    def _next_compare(self) -> None:
        if not self._compare_queue:
            return
        if not self._start_method("compare", self._compare_queue.pop(0)):
            self._compare_queue.clear()

    # ------------------------------------------------------------------ exports (atomic, ask before overwrite)

    def _save_path(self, title: str, filt: str) -> str | None:
        path, _ = QFileDialog.getSaveFileName(self, title, "", filt)  # the dialog asks before overwriting
        return path or None

    def export_map(self, kind: str) -> None:
        from corrlib.io import save_map

        if self.last_result is None or self.last_result.map_xy is None:
            self.show_error("run a method first: there is no map to export")
            return
        path = self._save_path("Export map", "Map (*.txt)" if kind == "txt" else "Result (*.npz)")
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
        path = self._save_path("Export coloured target", "PLY (*.ply)")
        if path:
            try:
                save_mesh(path, self.target.vertices, self.target.faces, colors)
            except (CorrError, OSError) as exc:
                self.show_error(str(exc))

    def open_texture_dialog(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Texture image", "", "Images (*.png *.jpg *.jpeg *.bmp)")
        if path:
            self.load_texture(path)

    def load_texture(self, path: str) -> None:
        from PIL import Image, UnidentifiedImageError

        try:
            with Image.open(path) as im:
                self.pair_view.texture_image = np.asarray(im.convert("RGB"))
        except (OSError, UnidentifiedImageError) as exc:
            self.show_error(f"{path}: cannot read the texture image: {exc}")
            return
        self.pair_view.mode.setCurrentText("texture")
        self.pair_view.redraw()

    def export_frames(self, suffix: str = ".obj", folder: str | None = None) -> list[Path]:
        """Write 11 frames from t = 0 to t max with the source's connectivity, ``animation.glb`` (glTF
        morph-target animation) and ``volumes.csv`` (asks before overwriting)."""
        from corrlib.morph import export_sequence

        if self.sequence_view.positions is None:
            self.show_error("no sequence to export (run a method on two meshes)")
            return []
        folder = folder or QFileDialog.getExistingDirectory(self, "Folder for the frames")
        if not folder:
            return []
        frames = list(self.sequence_view.frames(11))
        existing = [p for p in Path(folder).glob("frame_*") if p.suffix == suffix] + \
            [p for p in (Path(folder) / "animation.glb",) if p.exists()]
        if existing and self.interactive and QMessageBox.question(
                self, "corr studio", f"{len(existing)} frame files exist in {folder}. Overwrite them?") \
                != QMessageBox.Yes:
            return []
        try:
            written = export_sequence(folder, [v for _t, v in frames], self.source.faces, [t for t, _v in frames],
                                      fmt=suffix.lstrip("."), closed=self.source.is_closed)
        except (CorrError, OSError) as exc:
            self.show_error(str(exc))
            return []
        volumes = written["volume"]
        note = (f"largest volume change {max(abs(v / volumes[0] - 1) for v in volumes):.2e}"
                if volumes[0] is not None else "volume does not apply (open mesh)")
        self.job_panel.write(f"wrote {len(frames)} frames, animation.glb and volumes.csv to {folder} ({note})")
        return written["frames"]

    def export_strip(self) -> None:
        from PIL import Image

        from corrlib.io import atomic_write

        if self.sequence_view.positions is None:
            self.show_error("no sequence to export (run a method on two meshes)")
            return
        path = self._save_path("Sequence picture strip", "PNG (*.png)")
        if path:
            self.tabs.setCurrentWidget(self.sequence_view)
            strip = self.sequence_view.picture_strip()
            with atomic_write(path, "wb") as fh:
                Image.fromarray(strip).save(fh, format="PNG")

    def export_screenshot(self) -> None:
        path = self._save_path("Screenshot", "PNG (*.png)")
        if path:
            self.save_screenshot(path)

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

    def export_table(self) -> None:
        from corrlib.io import atomic_write

        rows = self.compare_view.table_rows()
        if not rows:
            self.show_error("the comparison table is empty")
            return
        path = self._save_path("Comparison table", "CSV (*.csv)")
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
        self.runner.shutdown()
        for view in (self.pair_view, self.product_view, self.sequence_view, self.retrieval_view, self.compare_view):
            view.close_plotters()
        super().closeEvent(event)
