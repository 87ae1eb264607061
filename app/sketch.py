"""Sketch canvas: draw a closed silhouette with the mouse, or load one; produces a Contour2D."""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QPointF, Qt, Signal
from PySide6.QtGui import QColor, QPainter, QPainterPath, QPen
from PySide6.QtWidgets import QGridLayout, QHBoxLayout, QLabel, QPushButton, QSpinBox, QVBoxLayout, QWidget

from corrlib.errors import CorrError
from corrlib.io import enclosed_outline
from corrlib.shapes import Contour2D, inspect_contour

MIN_CANVAS_SIZE = (240, 200)
MIN_STEP_PX = 2.0  # a drawn point is kept when the mouse moved at least this far from the last one
SKETCH_POINTS_RANGE = (10, 2000)
DEFAULT_SKETCH_POINTS = 200  # the sketch is resampled by arc length to this many points
FIT_MARGIN = 0.85  # a loaded contour fills this fraction of the canvas

def smooth_closed(points: np.ndarray, passes: int = 2) -> np.ndarray:
    """Laplacian smoothing of a closed polyline (each pass: average with both neighbours)."""
    p = np.asarray(points, dtype=np.float64)
    for _ in range(passes):
        p = 0.25 * np.roll(p, 1, axis=0) + 0.5 * p + 0.25 * np.roll(p, -1, axis=0)
    return p


class SketchArea(QWidget):
    """The drawing surface. A stroke is closed automatically when the mouse is released."""

    changed = Signal()

    def __init__(self, parent=None):
        super().__init__(parent)
        self.setMinimumSize(*MIN_CANVAS_SIZE)
        self.strokes: list[np.ndarray] = []  # history for undo; the last one is the current sketch
        self._current: list[tuple[float, float]] = []
        self.setMouseTracking(False)

    def points(self) -> np.ndarray | None:
        """(m, 2) widget coordinates of the current closed sketch (y down), or None."""
        return self.strokes[-1] if self.strokes else None

    def set_points(self, points: np.ndarray) -> None:
        self.strokes.append(np.asarray(points, dtype=np.float64))
        self.update()
        self.changed.emit()

    def undo(self) -> None:
        if self.strokes:
            self.strokes.pop()
            self.update()
            self.changed.emit()

    def clear(self) -> None:
        self.strokes.clear()
        self._current.clear()
        self.update()
        self.changed.emit()

    def mousePressEvent(self, event):
        if event.button() == Qt.LeftButton:
            self._current = [(event.position().x(), event.position().y())]

    def mouseMoveEvent(self, event):
        if self._current:
            x, y = event.position().x(), event.position().y()
            lx, ly = self._current[-1]
            if (x - lx) ** 2 + (y - ly) ** 2 >= MIN_STEP_PX ** 2:
                self._current.append((x, y))
                self.update()

    def mouseReleaseEvent(self, event):
        if event.button() == Qt.LeftButton and self._current:
            if len(self._current) >= 3:
                self.set_points(np.array(self._current))
            self._current = []
            self.update()

    def paintEvent(self, _event):
        painter = QPainter(self)
        painter.setRenderHint(QPainter.Antialiasing)
        painter.fillRect(self.rect(), QColor(252, 252, 250))
        pts = np.array(self._current) if self._current else self.points()
        if pts is not None and len(pts) >= 2:
            path = QPainterPath(QPointF(*pts[0]))
            for x, y in pts[1:]:
                path.lineTo(QPointF(x, y))
            path.closeSubpath()
            painter.fillPath(path, QColor(120, 160, 220, 120))  # filled while drawing
            painter.setPen(QPen(QColor(30, 50, 110), 2))
            painter.drawPath(path)
        painter.end()


class SketchPanel(QWidget):
    """Canvas plus undo/clear/smooth controls; :meth:`contour` returns the validated Contour2D."""

    contour_ready = Signal(object)  # Contour2D

    def __init__(self, parent=None):
        super().__init__(parent)
        self.area = SketchArea()
        self.status = QLabel("Draw a closed silhouette with the left mouse button.")
        self.status.setWordWrap(True)
        self.n_points = QSpinBox()
        self.n_points.setRange(*SKETCH_POINTS_RANGE)
        self.n_points.setValue(DEFAULT_SKETCH_POINTS)
        self.n_points.setToolTip("The sketch is resampled by arc length to this many points.")
        buttons = QGridLayout()  # two by two: the dock stays narrow on small screens
        for index, (text, slot) in enumerate((("Undo", self.area.undo), ("Clear", self.area.clear),
                                              ("Smooth", self.smooth), ("Use", self.emit_contour))):
            b = QPushButton(text)
            b.clicked.connect(slot)
            buttons.addWidget(b, index // 2, index % 2)
        layout = QVBoxLayout(self)
        layout.addWidget(self.area, 1)
        row = QHBoxLayout()
        row.addWidget(QLabel("Points"))
        row.addWidget(self.n_points)
        layout.addLayout(row)
        layout.addLayout(buttons)
        layout.addWidget(self.status)
        self.area.changed.connect(self._describe)

    def smooth(self) -> None:
        pts = self.area.points()
        if pts is not None:
            self.area.set_points(smooth_closed(pts))

    def show_contour(self, contour: Contour2D) -> None:
        """Display a loaded contour, fitted into the canvas."""
        p = contour.points.copy()
        p[:, 1] *= -1  # contours have y up, the widget y down
        lo, hi = p.min(axis=0), p.max(axis=0)
        scale = FIT_MARGIN * min(self.area.width() / max(hi[0] - lo[0], 1e-9), self.area.height() / max(hi[1] - lo[1], 1e-9))
        centre = np.array([self.area.width(), self.area.height()]) / 2
        self.area.set_points((p - (lo + hi) / 2) * scale + centre)
        self.status.setText(f"{contour.name}: {contour.n_points} points, loaded as the query")

    def contour(self) -> Contour2D:
        pts = self.area.points()
        if pts is None:
            raise CorrError("the sketch is empty: draw a closed silhouette first")
        p = pts.copy()
        p[:, 1] *= -1
        contour = Contour2D(p, name="sketch").ccw()
        return contour.resample(self.n_points.value())

    def outline_crossed_stroke(self) -> bool:
        """Replace a stroke that crosses itself by the outline of the region it encloses
        (:func:`~corrlib.io.enclosed_outline`): a hand-drawn stroke overshoots its start when it is closed, or
        loops where the hand shook, and a polygon that crosses itself has no inside to match. The canvas shows
        the outline (Undo brings the stroke back). Returns whether the stroke was replaced."""
        pts = self.area.points()
        if pts is None or not any(f.code == "self-intersection" for f in inspect_contour(pts)):
            return False
        self.area.set_points(enclosed_outline(pts, name="sketch"))  # y down in and out: the raster is y-blind
        return True

    def emit_contour(self) -> None:
        try:
            replaced = self.outline_crossed_stroke()
            contour = self.contour()
        except CorrError as exc:
            self.status.setText(f"<span style='color:#b00020'>{exc}</span>")
            return
        note = (" The stroke crossed itself, so the outline of the region it encloses is used (Undo brings the "
                "stroke back).") if replaced else ""
        self.status.setText(f"sketch: {contour.n_points} points, ready as a query.{note}")
        self.contour_ready.emit(contour)

    def _describe(self) -> None:
        pts = self.area.points()
        self.status.setText("empty" if pts is None else f"{len(pts)} drawn points (press Use)")
