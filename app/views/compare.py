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
from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QComboBox,
    QHBoxLayout,
    QHeaderView,
    QListWidget,
    QListWidgetItem,
    QPushButton,
    QSplitter,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from app.views.scene import (
    ERROR_COLOR_MAX,
    PLAIN_COLOR,
    coordinate_colors,
    make_plotter,
    polydata,
    transfer_colors,
)

#: table columns: header and tooltip
COLUMNS = (("method", "registered method"), ("s", "runtime in seconds"), ("energy", "the method's own objective"),
           ("mean", "mean geodesic error / sqrt(area) against the ground truth"),
           ("mean sym", "the same, a match to the mirror-image partner also accepted (needs <target>.sym.vts)"),
           ("≤0.05", "fraction of ground-truth points within 0.05"), ("AUC", "area under the cumulative curve"),
           ("unmatched", "source vertices left unmatched"))
#: what the method views show
COLOR_MODES = ("colour transfer", "error heat map")
METHOD_LIST_WIDTH = 220
TABLE_CURVES_SPLIT = [620, 300]  # initial widths of the table and the error-curve plot
VIEWS_BOTTOM_SPLIT = [500, 250]  # initial heights of the views and the table/plot row
LABEL_FONT_SIZE = 8


class CompareView(QWidget):
    """Queue of methods; each result adds a column of views, a table row and an error curve."""

    def __init__(self, parent=None):
        super().__init__(parent)
        self.methods = QListWidget()
        self.methods.setMaximumWidth(METHOD_LIST_WIDTH)
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
        self.table.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeToContents)
        self.table.horizontalHeader().setSortIndicator(-1, Qt.AscendingOrder)  # insertion order until a click
        self.table.setSortingEnabled(True)
        self.figure = Figure(figsize=(4, 3))
        self.canvas = FigureCanvasQTAgg(self.figure)
        self.plotter = None
        self.views_box = QVBoxLayout()
        left = QVBoxLayout()
        left.addWidget(self.methods, 1)
        left.addWidget(self.run_button)
        left.addWidget(self.color_mode)
        left_w = QWidget()
        left_w.setLayout(left)
        views_w = QWidget()
        views_w.setLayout(self.views_box)
        bottom = QSplitter(Qt.Horizontal)
        bottom.addWidget(self.table)
        bottom.addWidget(self.canvas)
        bottom.setSizes(TABLE_CURVES_SPLIT)
        right = QSplitter(Qt.Vertical)
        right.addWidget(views_w)
        right.addWidget(bottom)
        right.setSizes(VIEWS_BOTTOM_SPLIT)
        layout = QHBoxLayout(self)
        layout.addWidget(left_w)
        layout.addWidget(right, 1)
        self.rows: list[dict] = []
        self.shapes = None  # (source, target) of the current comparison

    def set_methods(self, specs) -> None:
        self.methods.clear()
        for spec in specs:
            item = QListWidgetItem(spec.label)
            item.setData(Qt.UserRole, spec.name)
            item.setFlags(item.flags() | Qt.ItemIsUserCheckable)
            item.setCheckState(Qt.Checked)
            self.methods.addItem(item)

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
            self.views_box.removeWidget(self.plotter.interactor)
            self.plotter.close()
            self.plotter.interactor.deleteLater()
            self.plotter = None
        if n_methods:
            self.plotter = make_plotter(self, shape=grid_shape(n_methods + 1))
            self.views_box.addWidget(self.plotter.interactor)

    def add_result(self, source, target, result, report=None, n_unmatched: int = 0, per_vertex=None) -> None:
        """Add one method's result.

        ``report``: an ErrorReport of the matched ground-truth rows when ground
        truth is known (with mirror-accepted errors if the mirrored rows were
        given); ``n_unmatched``: source vertices the map leaves unmatched (-1;
        left out of the error columns); ``per_vertex``: (n_x,) direct error of
        every source vertex with ground truth, NaN elsewhere (the heat map).
        """
        summary = report.summary() if report is not None else {}
        row = {"method": result.method, "runtime": result.timings.get("total", np.nan), "energy": result.energy,
               "mean": summary.get("mean", np.nan), "mean_sym": summary.get("mean_sym", np.nan),
               "within": summary.get("within_0.05", np.nan), "auc": summary.get("auc", np.nan),
               "unmatched": n_unmatched, "result": result, "report": report, "per_vertex": per_vertex}
        self.rows.append(row)
        self.shapes = (source, target)
        self.table.setSortingEnabled(False)  # rows are filled at their insertion position
        r = self.table.rowCount()
        self.table.insertRow(r)
        values = (row["method"], row["runtime"], row["energy"], row["mean"], row["mean_sym"], row["within"],
                  row["auc"], n_unmatched)
        for c, v in enumerate(values):
            self.table.setItem(r, c, table_item(v))
        self.table.setSortingEnabled(True)
        self._draw_view(len(self.rows))
        self._draw_curves()

    def _view_position(self, index: int) -> tuple[int, int] | None:
        """Grid cell of view ``index`` (0: the source), None beyond the grid."""
        rows, cols = self.plotter.shape
        return (index // cols, index % cols) if index < rows * cols else None

    def _redraw_views(self) -> None:
        """Draw every view again (after a change of colour mode)."""
        if self.plotter is None or not self.rows:
            return
        self.plotter.clear_actors()
        for index in range(1, len(self.rows) + 1):
            self._draw_view(index, reset_camera=False)
        self.plotter.render()

    def _draw_view(self, index: int, reset_camera: bool = True) -> None:
        """View ``index``: the source (drawn with the first result), or the result of row ``index - 1``."""
        if self.plotter is None or self.shapes is None:
            return
        source, target = self.shapes
        colors = coordinate_colors(source.vertices)
        heat = self.color_mode.currentText() == "error heat map"
        if index == 1:
            self.plotter.subplot(0, 0)
            self.plotter.add_mesh(polydata(source.vertices, source.faces), scalars=colors, rgb=True)
            self.plotter.add_text("source", font_size=LABEL_FONT_SIZE)
        position = self._view_position(index)
        if position is None:
            return
        row = self.rows[index - 1]
        self.plotter.subplot(*position)
        map_yx, per_vertex = row["result"].map_yx, row["per_vertex"]
        if heat and per_vertex is not None:
            mesh = polydata(source.vertices, source.faces)
            mesh["error"] = spread_to_matched(source.vertices, per_vertex, row["result"].map_xy)
            self.plotter.add_mesh(mesh, scalars="error", cmap="inferno", clim=(0, ERROR_COLOR_MAX),
                                  nan_color=PLAIN_COLOR, show_scalar_bar=index == 1,
                                  scalar_bar_args={"title": "error", "n_labels": 4, "vertical": True,
                                                   "position_x": 0.85, "position_y": 0.15, "height": 0.7,
                                                   "width": 0.05, "label_font_size": 10, "title_font_size": 10})
            self.plotter.add_text(f"{row['method']} (error on the source)", font_size=LABEL_FONT_SIZE)
        elif heat:
            self.plotter.add_mesh(polydata(source.vertices, source.faces), color=PLAIN_COLOR)
            self.plotter.add_text(f"{row['method']}: no ground truth", font_size=LABEL_FONT_SIZE)
        elif map_yx is None:
            self.plotter.add_text(f"{row['method']}: no target map", font_size=LABEL_FONT_SIZE)
        else:
            tgt_colors = transfer_colors(colors, map_yx)
            self.plotter.add_mesh(polydata(target.vertices, target.faces), scalars=tgt_colors, rgb=True)
            self.plotter.add_text(row["method"], font_size=LABEL_FONT_SIZE)
        self.plotter.link_views()
        if reset_camera:
            self.plotter.reset_camera()
        self.plotter.render()

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
            ax.set_ylabel("% correspondences")
            ax.set_ylim(0, 100)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7)
        else:
            ax.text(0.5, 0.5, "load ground truth to see error curves", ha="center", va="center")
            ax.set_axis_off()
        self.figure.tight_layout()
        self.canvas.draw_idle()

    def table_rows(self) -> list[list[str]]:
        """The table's texts in display order (after any sorting by the user)."""
        return [[self.table.item(r, c).text() for c in range(self.table.columnCount())]
                for r in range(self.table.rowCount())]

    def close_plotters(self) -> None:
        if self.plotter is not None:
            self.plotter.close()


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


def table_item(value) -> QTableWidgetItem:
    """A cell for a method name (text) or a figure (4 significant digits, '—' if missing)."""
    if isinstance(value, str):
        return QTableWidgetItem(value)
    number = float("nan") if value is None else float(value)
    text = "—" if not np.isfinite(number) else (str(int(number)) if isinstance(value, (int, np.integer))
                                                 else f"{number:.4g}")
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
