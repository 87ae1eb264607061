"""Product view: a 2D-to-3D match (contour and mesh with the matched closed curve, coloured by position)."""

from __future__ import annotations

import numpy as np
from PySide6.QtWidgets import QLabel, QVBoxLayout, QWidget

from app.views.scene import LazyPlotter, hue_colors, polydata, polyline


class ProductView(QWidget):
    """Left: the query contour; right: the mesh with the matched curve; both coloured by contour position."""

    def __init__(self, parent=None):
        super().__init__(parent)
        self.info = QLabel("Match a contour to a mesh (2D-to-3D) to see the matched curve here. "
                           "Product-torus views of contour pairs appear when that method is available.")
        self.info.setWordWrap(True)
        layout = QVBoxLayout(self)
        layout.addWidget(self.info)
        plot_box = QVBoxLayout()
        layout.addLayout(plot_box, 1)
        self._plotter = LazyPlotter(self, plot_box, shape=(1, 2))
        self.curve = None  # the matched curve's polydata (for tests)

    @property
    def plotter(self):
        return self._plotter.get()

    def show_contour_match(self, contour_points: np.ndarray, mesh, path_vertices: np.ndarray,
                           path_contour_index: np.ndarray, energy: float) -> None:
        p = self.plotter
        p.clear_actors()
        m = contour_points.shape[0]
        p.subplot(0, 0)
        line = polyline(contour_points)
        line["position"] = np.arange(m) / m
        p.add_mesh(line, scalars=hue_colors(np.arange(m) / m), rgb=True, line_width=4)
        p.add_text("query contour", font_size=9)
        p.view_xy()
        p.reset_camera()
        p.subplot(0, 1)
        p.add_mesh(polydata(mesh.vertices, mesh.faces), color="lightgrey", smooth_shading=True)
        self.curve = polyline(mesh.vertices[path_vertices], closed=False)
        self.curve["colors"] = hue_colors(path_contour_index / m)  # carried onto the tube's points
        tube = self.curve.tube(radius=0.004 * mesh.bbox_diagonal)
        p.add_mesh(tube, scalars="colors", rgb=True)
        p.add_text(f"{mesh.name}: matched curve (energy {energy:.4g})", font_size=9)
        p.reset_camera()
        p.subplot(0, 0)
        p.reset_camera()
        p.render()
        self.info.setText(f"{m} contour points matched along a closed curve of {len(path_vertices)} steps.")

    def close_plotters(self) -> None:
        self._plotter.close()
