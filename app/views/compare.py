"""Compare view: several methods on one pair in a grid with one camera, a sortable table and error curves.

Every view shows one method's result, either as the source's colours
transferred to the target, or (with ground truth) as a heat map of every
source vertex's direct error on one shared colour scale, where a left/right
flip shows as a glowing limb. The table gives the direct and the
mirror-accepted mean error side by side (the latter where the target's
mirrored ground truth was loaded).
"""

from __future__ import annotations

import math

import numpy as np
from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
from matplotlib.figure import Figure
from PySide6.QtCore import Qt, QTimer, Signal
from PySide6.QtWidgets import (
    QComboBox,
    QHBoxLayout,
    QHeaderView,
    QListWidget,
    QListWidgetItem,
    QPushButton,
    QSizePolicy,
    QSplitter,
    QStyle,
    QTableWidget,
    QTableWidgetItem,
    QTabWidget,
    QVBoxLayout,
    QWidget,
)

from app.views.camera import Displayed, FramedView, enable_hover, picked_vertex
from app.views.scene import (
    ERROR_BAR_TITLE,
    ERROR_COLOR_MAX,
    PLAIN_COLOR,
    add_caption,
    close_plotter,
    coordinate_colors,
    make_plotter,
    polydata,
    transfer_colors,
)
from corrlib.evaluation import image_area_share

#: table columns: header and tooltip. The methods' own objectives are not a column: they measure different
#: things and do not sort against each other; each is in its method's tooltip (:func:`objective_tip`).
COLUMNS = (("method", "registered method (its own objective in the tooltip)"), ("s", "runtime in seconds"),
           ("mean", "mean geodesic error / sqrt(area) against the ground truth"),
           ("mean sym", "the same, a match to the mirror-image partner also accepted (needs <target>.sym.vts)"),
           ("≤0.05", "fraction of ground-truth points within 0.05"), ("AUC", "area under the cumulative curve"),
           ("reach", "share of the target's area the map reaches (the vertices some source vertex is sent to; "
                     "1 for a map onto every vertex, less where it piles onto few and leaves parts unreached)"),
           ("unmatched", "source vertices left unmatched"))
#: what the method views show
COLOR_MODES = ("colour transfer", "error heat map")
METHOD_LIST_ROWS = 2  # the method check list's height before its items are laid out (then: fit_method_strip)
MAX_METHOD_LIST_ROWS = 4  # beyond this many rows of methods the strip scrolls
VIEWS_BOTTOM_SPLIT = [640, 260]  # initial heights of the grid and the table/curves tabs
CAPTION_PX = 12  # the grid's views are small: a pixel less than the other views' captions
MARKER_SIZE = 14  # point inspection: pixels of the markers
PARTNER_COLOR = "black"  # the method's partner of the inspected vertex
TRUE_PARTNER_COLOR = "lime"  # its ground-truth partner


class CompareView(QWidget, FramedView):
    """Queue of methods; each result adds a view to the grid, a table row and an error curve.

    Point inspection: a click on a shape (or :meth:`inspect`) marks a source
    vertex on the source view and, in every method's view, its partner under
    that method (black) and, with ground truth, its true partner (green),
    with the geodesic error in the view's caption.
    """

    hovered = Signal(str)  # "vertex i of <shape>" under the mouse

    def __init__(self, parent=None):
        super().__init__(parent)
        self.methods = QListWidget()  # a wrapping strip of check boxes, so the grid gets the width
        self.unticked: set[str] = set()  # the methods the user unticked (set_methods keeps them so)
        self.methods.setFlow(QListWidget.LeftToRight)
        self.methods.setWrapping(True)
        self.methods.setResizeMode(QListWidget.Adjust)
        self.methods.setSizePolicy(QSizePolicy.Expanding, QSizePolicy.Fixed)  # as high as fit_method_strip says
        self.methods.setFixedHeight(METHOD_LIST_ROWS * self.methods.fontMetrics().height() + 16)
        self.run_button = QPushButton("Run selected")
        self.color_mode = QComboBox()
        self.color_mode.addItems(COLOR_MODES)
        self.color_mode.setToolTip("Colours transferred through each map, or each source vertex's geodesic error "
                                   "(needs ground truth; one colour scale for all methods)")
        self.color_mode.currentIndexChanged.connect(lambda _: self._redraw_views())
        self.table = QTableWidget(0, len(COLUMNS))
        self.table.setHorizontalHeaderLabels([name for name, _ in COLUMNS])
        for c, (_, tip) in enumerate(COLUMNS):
            self.table.horizontalHeaderItem(c).setToolTip(tip)
        header = self.table.horizontalHeader()
        header.setSectionResizeMode(QHeaderView.ResizeToContents)  # every figure read whole
        header.setStretchLastSection(True)  # a wide table has no empty strip at the right
        rows = self.table.verticalHeader()
        rows.setVisible(False)  # a row is named by its method
        rows.setDefaultSectionSize(self.table.fontMetrics().height() + 8)
        self.table.horizontalHeader().setSortIndicator(-1, Qt.AscendingOrder)  # insertion order until a click
        self.table.setSortingEnabled(True)
        self.figure = Figure(figsize=(4, 3), layout="constrained")  # fits labels into any size
        self.canvas = FigureCanvasQTAgg(self.figure)
        self.plotter = None
        self.retired_plotters = []  # closed grids of earlier comparisons (see clear_results)
        self.views_box = QVBoxLayout()
        top = QHBoxLayout()
        top.addWidget(self.methods, 1)
        controls = QVBoxLayout()
        controls.addWidget(self.run_button)
        controls.addWidget(self.color_mode)
        top.addLayout(controls)
        views_w = QWidget()
        views_w.setLayout(self.views_box)
        self.bottom = QTabWidget()  # the table and the curves each get the full width
        self.bottom.addTab(self.table, "Table")
        self.bottom.addTab(self.canvas, "Error curves")
        self.splitter = QSplitter(Qt.Vertical)
        self.splitter.addWidget(views_w)
        self.splitter.addWidget(self.bottom)
        self.splitter.setSizes(VIEWS_BOTTOM_SPLIT)
        layout = QVBoxLayout(self)
        layout.addLayout(top)
        layout.addWidget(self.splitter, 1)
        self.rows: list[dict] = []
        self.shapes = None  # (source, target) of the current comparison
        self.displayed: Displayed | None = None  # source and target in their display frames
        self.true_partner: np.ndarray | None = None  # (n_x,) ground-truth target vertex, -1 where unknown
        self.inspected: int | None = None  # the source vertex under inspection
        self.captions: dict[int, str] = {}  # view index -> caption (for tests and the picture)

    def set_methods(self, specs) -> None:
        """The methods that can be compared on the pair loaded, each ticked as the user last left it (a method not
        listed before is ticked), so that a new pair does not bring back the slow methods the user unticked."""
        for i in range(self.methods.count()):  # remembered also across pairs the methods do not take (contours)
            item = self.methods.item(i)
            if item.checkState() == Qt.Checked:
                self.unticked.discard(item.data(Qt.UserRole))
            else:
                self.unticked.add(item.data(Qt.UserRole))
        self.methods.clear()
        for spec in specs:
            item = QListWidgetItem(spec.label)
            item.setData(Qt.UserRole, spec.name)
            item.setFlags(item.flags() | Qt.ItemIsUserCheckable)
            item.setCheckState(Qt.Unchecked if spec.name in self.unticked else Qt.Checked)
            self.methods.addItem(item)
        self.fit_method_strip()

    def selected(self) -> list[str]:
        return [self.methods.item(i).data(Qt.UserRole) for i in range(self.methods.count())
                if self.methods.item(i).checkState() == Qt.Checked]

    def clear_results(self, n_methods: int = 0) -> None:
        """Reset for a new comparison of ``n_methods`` methods (one view each, plus the source)."""
        self.rows = []
        self.table.setRowCount(0)
        self.figure.clear()
        self.canvas.draw_idle()
        if self.plotter is not None:
            # the closed grid is hidden and kept until the window goes: deleting closed VTK widgets is where the
            # studio's tests crashed now and then (docs/decisions.md, seventeenth session)
            self.views_box.removeWidget(self.plotter.interactor)
            close_plotter(self.plotter)
            self.plotter.interactor.hide()
            self.retired_plotters.append(self.plotter)
            self.plotter = None
        self.inspected = None
        self.captions = {}
        if n_methods:
            self.plotter = make_plotter(self, shape=grid_shape(n_methods + 1))
            self.views_box.addWidget(self.plotter.interactor)
            self.plotter.enable_point_picking(callback=self._on_pick, show_message=False, use_picker=True,
                                              left_clicking=True, show_point=False)
            enable_hover(self.plotter, self._hover_text, self.hovered.emit)

    def set_ground_truth(self, source_rows, target_rows, n_source: int) -> None:
        """Ground-truth rows (or None) of the pair being compared: the true partners of inspected vertices."""
        self.true_partner = None
        if source_rows is not None:
            self.true_partner = np.full(n_source, -1, dtype=np.int64)
            self.true_partner[np.asarray(source_rows)] = np.asarray(target_rows)

    def framed_points(self) -> list[np.ndarray]:
        return [] if self.displayed is None else list(self.displayed.points)

    def has_results(self) -> bool:
        """Whether the grid shows at least one method's result."""
        return self.plotter is not None and bool(self.rows)

    def redraw(self) -> None:
        self._redraw_views(reset_camera=True)

    def add_result(self, source, target, result, report=None, n_unmatched: int = 0, per_vertex=None) -> None:
        """Add one method's result.

        ``report``: an ErrorReport of the matched ground-truth rows when ground
        truth is known (with mirror-accepted errors if the mirrored rows were
        given); ``n_unmatched``: source vertices the map leaves unmatched (-1;
        left out of the error columns); ``per_vertex``: (n_x,) direct error of
        every source vertex with ground truth, NaN elsewhere (the heat map).
        """
        summary = report.summary() if report is not None else {}
        row = {"method": result.method, "runtime": result.timings.get("total", np.nan),
               "mean": summary.get("mean", np.nan), "mean_sym": summary.get("mean_sym", np.nan),
               "within": summary.get("within_0.05", np.nan), "auc": summary.get("auc", np.nan),
               "unmatched": n_unmatched, "result": result, "report": report, "per_vertex": per_vertex}
        self.rows.append(row)
        self.shapes = (source, target)
        self.displayed = Displayed.of(self.shapes, self.up, reuse=self.displayed)
        self.table.setSortingEnabled(False)  # rows are filled at their insertion position
        r = self.table.rowCount()
        self.table.insertRow(r)
        values = (row["method"], row["runtime"], row["mean"], row["mean_sym"], row["within"], row["auc"],
                  image_area_share(result.map_xy, target), n_unmatched)
        for c, v in enumerate(values):
            self.table.setItem(r, c, table_item(v))
        self.table.item(r, 0).setToolTip(objective_tip(result))
        self.table.setSortingEnabled(True)
        self.fit_table()
        self._draw_view(len(self.rows))
        self._draw_curves()

    def fit_method_strip(self) -> None:
        """The method check list as high as its wrapped rows (up to :data:`MAX_METHOD_LIST_ROWS`): a narrow window
        wraps the methods onto a third row, which a strip of two rows half hid."""
        strip = self.methods
        if strip.count() == 0:
            return
        strip.doItemsLayout()
        row_px = strip.visualItemRect(strip.item(0)).height()
        bottom = max(strip.visualItemRect(strip.item(i)).bottom() + strip.verticalOffset()
                     for i in range(strip.count()))
        strip.setFixedHeight(min(bottom + 1, MAX_METHOD_LIST_ROWS * row_px) + 2 * strip.frameWidth() + 2)

    def resizeEvent(self, event) -> None:  # noqa: N802 (Qt's name)
        super().resizeEvent(event)
        QTimer.singleShot(0, self.fit_method_strip)  # once the strip has its new width

    def fit_table(self) -> None:
        """The table and curves tabs made tall enough for every row of the table, up to half of the tab's height
        (a small window's grid had the table show two methods of five); a taller pane the user chose stays."""
        table = self.table
        rows_px = sum(table.rowHeight(r) for r in range(table.rowCount()))
        scrollbar_px = table.style().pixelMetric(QStyle.PM_ScrollBarExtent, None, table)  # shown when narrow
        table_px = table.horizontalHeader().sizeHint().height() + rows_px + scrollbar_px + 2 * table.frameWidth() + 2
        needed = table_px + self.bottom.tabBar().sizeHint().height() + 4
        views_px, bottom_px = self.splitter.sizes()
        wanted = min(needed, (views_px + bottom_px) // 2)
        if bottom_px < wanted:
            self.splitter.setSizes([views_px + bottom_px - wanted, wanted])

    def _view_position(self, index: int) -> tuple[int, int] | None:
        """Grid cell of view ``index`` (0: the source), None beyond the grid."""
        rows, cols = self.plotter.shape
        return (index // cols, index % cols) if index < rows * cols else None

    def _redraw_views(self, reset_camera: bool = False) -> None:
        """Draw every view again (after a change of colour mode, up axis or inspected vertex)."""
        if self.plotter is None or not self.rows:
            return
        self.displayed = Displayed.of(self.shapes, self.up, reuse=self.displayed)
        self.plotter.clear_actors()
        for index in range(1, len(self.rows) + 1):
            self._draw_view(index, reset_camera=False)
        if reset_camera:
            self.fit_preset()
        self.plotter.render()

    def _draw_view(self, index: int, reset_camera: bool = True) -> None:
        """View ``index``: the source (drawn with the first result), or the result of row ``index - 1``."""
        if self.plotter is None or self.shapes is None:
            return
        source, target = self.shapes
        src_points, tgt_points = self.framed_points()
        colors = coordinate_colors(source.vertices)
        heat = self.color_mode.currentText() == "error heat map"
        v = self.inspected
        if index == 1:
            self.plotter.subplot(0, 0)
            self.plotter.add_mesh(polydata(src_points, source.faces), scalars=colors, rgb=True)
            caption = "source" if v is None else f"source: vertex {v}"
            self._caption(0, caption)
            if v is not None:
                self._marker(src_points[v], PARTNER_COLOR)
        position = self._view_position(index)
        if position is None:
            return
        row = self.rows[index - 1]
        self.plotter.subplot(*position)
        result = row["result"]
        map_yx, map_xy, per_vertex = result.map_yx, result.map_xy, row["per_vertex"]
        error = None if v is None or per_vertex is None or not np.isfinite(per_vertex[v]) else float(per_vertex[v])
        if heat and per_vertex is not None:
            mesh = polydata(src_points, source.faces)
            mesh["error"] = spread_to_matched(source.vertices, per_vertex, map_xy)
            self.plotter.add_mesh(mesh, scalars="error", cmap="inferno", clim=(0, ERROR_COLOR_MAX),
                                  nan_color=PLAIN_COLOR, show_scalar_bar=index == 1,
                                  scalar_bar_args={"title": ERROR_BAR_TITLE, "n_labels": 4, "vertical": True,
                                                   "position_x": 0.85, "position_y": 0.15, "height": 0.7,
                                                   "width": 0.05, "label_font_size": 10, "title_font_size": 10})
            caption = f"{row['method']} (error on the source)"
            if v is not None:
                self._marker(src_points[v], PARTNER_COLOR)
                caption += f"\nvertex {v}: error {error:.3f}" if error is not None else f"\nvertex {v}: no error"
        elif heat:
            self.plotter.add_mesh(polydata(src_points, source.faces), color=PLAIN_COLOR)
            caption = f"{row['method']}: no ground truth"
        elif map_yx is None:
            caption = f"{row['method']}: no target map"
        else:
            tgt_colors = transfer_colors(colors, map_yx)
            self.plotter.add_mesh(polydata(tgt_points, target.faces), scalars=tgt_colors, rgb=True)
            caption = row["method"]
            if v is not None:
                caption += "\n" + self._partner_caption(v, map_xy, error, tgt_points)
        self._caption(index, caption)
        self.plotter.link_views()
        if reset_camera:
            self.fit_preset()
        self.plotter.render()

    def _partner_caption(self, v: int, map_xy, error, tgt_points) -> str:
        """Marks the partner and the true partner of source vertex ``v``; their caption line."""
        partner = -1 if map_xy is None else int(map_xy[v])
        text = f"{v} -> {partner}" if partner >= 0 else f"{v}: unmatched"
        if partner >= 0:
            self._marker(tgt_points[partner], PARTNER_COLOR)
        true = -1 if self.true_partner is None else int(self.true_partner[v])
        if true >= 0:
            self._marker(tgt_points[true], TRUE_PARTNER_COLOR)
            text += f" (true {true}" + (f", error {error:.3f})" if error is not None else ")")
        return text

    def _caption(self, index: int, text: str) -> None:
        self.captions[index] = text
        add_caption(self.plotter, text, CAPTION_PX)

    def _marker(self, point: np.ndarray, color: str) -> None:
        self.plotter.add_points(np.asarray(point, dtype=np.float64)[None], color=color, point_size=MARKER_SIZE,
                                render_points_as_spheres=True, pickable=False, reset_camera=False)

    def inspect(self, vertex: int | None) -> None:
        """Mark source vertex ``vertex`` and its partners in every view (None: clear the marks)."""
        if self.shapes is None:
            return
        if vertex is not None and not 0 <= int(vertex) < self.shapes[0].n_vertices:
            raise IndexError(f"vertex {vertex} is not a vertex of the source ({self.shapes[0].n_vertices} vertices)")
        self.inspected = None if vertex is None else int(vertex)
        self._redraw_views()

    def _view_of(self, renderer) -> int | None:
        renderers = list(self.plotter.renderers) if self.plotter is not None else []
        return renderers.index(renderer) if renderer in renderers else None

    def _shape_under(self, view: int | None) -> str | None:
        """"source" or "target": what view ``view`` shows (None: nothing)."""
        if view is None or self.shapes is None or view > len(self.rows):
            return None
        if view == 0 or self.color_mode.currentText() == "error heat map":
            return "source"
        return "target" if self.rows[view - 1]["result"].map_yx is not None else None

    def _on_pick(self, point, picker) -> None:
        """A click: the source vertex under it, or the source vertex mapped to the target vertex under it."""
        view = self._view_of(picker.GetRenderer())
        shape = self._shape_under(view)
        if shape is None or point is None:
            return
        src_points, tgt_points = self.framed_points()
        vertex = picked_vertex(src_points if shape == "source" else tgt_points, point)
        if shape == "target":
            vertex = int(self.rows[view - 1]["result"].map_yx[vertex])
            if vertex < 0:
                return
        self.inspect(vertex)

    def _hover_text(self, renderer, point) -> str | None:
        shape = self._shape_under(self._view_of(renderer))
        if shape is None:
            return None
        src_points, tgt_points = self.framed_points()
        index = 0 if shape == "source" else 1
        vertex = picked_vertex((src_points, tgt_points)[index], point)
        return f"vertex {vertex} of the {shape} ({self.shapes[index].name})"

    def _draw_curves(self) -> None:
        from corrlib.evaluation import cumulative_curve

        self.figure.clear()
        ax = self.figure.add_subplot(1, 1, 1)
        drawn = False
        for row in self.rows:
            report = row["report"]
            if report is not None:
                ax.plot(report.thresholds, 100 * cumulative_curve(report.errors, report.thresholds),
                        label=row["method"])
                drawn = True
        if drawn:
            ax.set_xlabel("geodesic error")
            ax.set_ylabel("% of points")  # within the error (short: a small window cut a longer label)
            ax.set_ylim(0, 100)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7)
        else:
            ax.text(0.5, 0.5, "load ground truth to see error curves", ha="center", va="center")
            ax.set_axis_off()
        self.canvas.draw_idle()

    def table_rows(self) -> list[list[str]]:
        """The table's texts in display order (after any sorting by the user)."""
        return [[self.table.item(r, c).text() for c in range(self.table.columnCount())]
                for r in range(self.table.rowCount())]

    def close_plotters(self) -> None:
        if self.plotter is not None:
            close_plotter(self.plotter)


def grid_shape(n_views: int) -> tuple[int, int]:
    """(rows, columns) of a near-square grid for ``n_views`` views, wider than tall."""
    cols = math.ceil(math.sqrt(n_views))
    return math.ceil(n_views / cols), cols


class _NumericItem(QTableWidgetItem):
    """A table cell that sorts by its number (NaN last), not by its text."""

    def __init__(self, text: str, value: float):
        super().__init__(text)
        self.value = value

    def __lt__(self, other):
        if isinstance(other, _NumericItem):
            a, b = self.value, other.value
            return (not math.isnan(a) and (math.isnan(b) or a < b))
        return super().__lt__(other)


def objective_tip(result) -> str:
    """The method's own objective, named, for its row's tooltip (it compares runs of one method only)."""
    energy = float("nan") if result.energy is None else float(result.energy)
    meaning = result.energy_meaning or "objective"
    return f"{result.method}: {meaning} {energy:.6g}" if np.isfinite(energy) else f"{result.method}: no objective"


def table_item(value) -> QTableWidgetItem:
    """A cell for a method name (text) or a figure (3 significant digits, '—' if missing; sorted by its value)."""
    if isinstance(value, str):
        return QTableWidgetItem(value)
    number = float("nan") if value is None else float(value)
    text = "—" if not np.isfinite(number) else (str(int(number)) if isinstance(value, (int, np.integer))
                                                 else f"{number:.3g}")
    return _NumericItem(text, number if np.isfinite(number) else float("nan"))


def spread_to_matched(vertices: np.ndarray, per_vertex: np.ndarray, map_xy) -> np.ndarray:
    """(n,) errors for display: a matched vertex without ground truth takes its nearest scored vertex's error.

    Ground truth usually covers a subset of the vertices; left as NaN they would speckle the heat map.
    Unmatched vertices (``map_xy`` -1) stay NaN (drawn grey).
    """
    from scipy.spatial import cKDTree

    values = np.asarray(per_vertex, dtype=np.float64).copy()
    scored = np.flatnonzero(np.isfinite(values))
    matched = np.ones(values.size, dtype=bool) if map_xy is None else np.asarray(map_xy) >= 0
    fill = np.flatnonzero(~np.isfinite(values) & matched)
    if scored.size and fill.size:
        values[fill] = values[scored[cKDTree(vertices[scored]).query(vertices[fill])[1]]]
    return values
