"""Compare view: several methods on one pair, side by side with one camera, a table and error curves."""

from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
from matplotlib.figure import Figure
from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
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

from app.views.scene import coordinate_colors, make_plotter, polydata, transfer_colors

COLUMNS = ("method", "runtime [s]", "energy", "mean error", "within 0.05", "AUC", "unmatched")
METHOD_LIST_WIDTH = 220
TABLE_CURVES_SPLIT = [520, 380]  # initial widths of the table and the error-curve plot
VIEWS_BOTTOM_SPLIT = [500, 250]  # initial heights of the views and the table/plot row
LABEL_FONT_SIZE = 8


class CompareView(QWidget):
    """Queue of methods; each result adds a column of views, a table row and an error curve."""

    def __init__(self, parent=None):
        super().__init__(parent)
        self.methods = QListWidget()
        self.methods.setMaximumWidth(METHOD_LIST_WIDTH)
        self.run_button = QPushButton("Run selected")
        self.table = QTableWidget(0, len(COLUMNS))
        self.table.setHorizontalHeaderLabels(COLUMNS)
        self.table.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeToContents)
        self.figure = Figure(figsize=(4, 3))
        self.canvas = FigureCanvasQTAgg(self.figure)
        self.plotter = None
        self.views_box = QVBoxLayout()
        left = QVBoxLayout()
        left.addWidget(self.methods, 1)
        left.addWidget(self.run_button)
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
            self.plotter = make_plotter(self, shape=(1, n_methods + 1))
            self.views_box.addWidget(self.plotter.interactor)

    def add_result(self, source, target, result, report=None, n_unmatched: int = 0) -> None:
        """Add one method's result.

        ``report``: an ErrorReport of the matched ground-truth rows when ground
        truth is known; ``n_unmatched``: source vertices the map leaves unmatched
        (-1; left out of the error columns).
        """
        summary = report.summary() if report is not None else {}
        row = {"method": result.method, "runtime": result.timings.get("total", np.nan), "energy": result.energy,
               "mean": summary.get("mean", np.nan), "within": summary.get("within_0.05", np.nan),
               "auc": summary.get("auc", np.nan), "unmatched": n_unmatched, "result": result, "report": report}
        self.rows.append(row)
        r = self.table.rowCount()
        self.table.insertRow(r)
        values = (row["method"], row["runtime"], row["energy"], row["mean"], row["within"], row["auc"])
        for c, v in enumerate(values + (str(n_unmatched),)):
            text = v if isinstance(v, str) else ("—" if v is None or not np.isfinite(v) else f"{v:.4g}")
            self.table.setItem(r, c, QTableWidgetItem(text))
        self._draw_views(source, target)
        self._draw_curves()

    def _draw_views(self, source, target) -> None:
        if self.plotter is None:
            return
        colors = coordinate_colors(source.vertices)
        if len(self.rows) == 1:
            self.plotter.subplot(0, 0)
            self.plotter.add_mesh(polydata(source.vertices, source.faces), scalars=colors, rgb=True)
            self.plotter.add_text("source", font_size=LABEL_FONT_SIZE)
        i = len(self.rows)
        if i >= self.plotter.shape[1]:
            return
        row = self.rows[-1]
        self.plotter.subplot(0, i)
        map_yx = row["result"].map_yx
        if map_yx is None:
            self.plotter.add_text(f"{row['method']}: no target map", font_size=LABEL_FONT_SIZE)
        else:
            tgt_colors = transfer_colors(colors, map_yx)
            self.plotter.add_mesh(polydata(target.vertices, target.faces), scalars=tgt_colors, rgb=True)
            self.plotter.add_text(row["method"], font_size=LABEL_FONT_SIZE)
        self.plotter.link_views()
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
        return [[self.table.item(r, c).text() for c in range(self.table.columnCount())]
                for r in range(self.table.rowCount())]

    def close_plotters(self) -> None:
        if self.plotter is not None:
            self.plotter.close()
