"""Pair view: source and target side by side with linked cameras, coloured through the map."""

from __future__ import annotations

import numpy as np
import pyvista as pv
from PySide6.QtWidgets import QComboBox, QHBoxLayout, QLabel, QVBoxLayout, QWidget

from app.views.scene import coordinate_colors, polydata, make_plotter
from corrlib.geometry.uv import checkerboard, cylindrical_uv

MODES = ("coordinates", "texture", "error")


class PairView(QWidget):
    """Colour transfer (``colors_Y = colors_X[map_yx]``), texture transfer and error heat map."""

    def __init__(self, parent=None):
        super().__init__(parent)
        self.plotter = make_plotter(self, shape=(1, 2))
        self.mode = QComboBox()
        self.mode.addItems(MODES)
        self.mode.setToolTip("coordinates: source coloured by position; texture: a checkerboard on a "
                             "cylindrical UV map of the source; error: geodesic error (ground truth needed)")
        self.mode.currentTextChanged.connect(self.redraw)
        self.info = QLabel("Load a source and a target mesh, then run a method.")
        top = QHBoxLayout()
        top.addWidget(QLabel("Show"))
        top.addWidget(self.mode)
        top.addWidget(self.info, 1)
        layout = QVBoxLayout(self)
        layout.addLayout(top)
        layout.addWidget(self.plotter.interactor, 1)
        self.source = self.target = None
        self.result = None
        self.errors = None  # (n_x,) per-vertex errors of the source, NaN where unknown
        self.target_colors: np.ndarray | None = None

    def set_shapes(self, source, target) -> None:
        self.source, self.target, self.result, self.errors = source, target, None, None
        self.info.setText("Run a method to see the correspondence.")
        self.redraw()

    def set_result(self, result, errors: np.ndarray | None = None) -> None:
        self.result = result
        self.errors = errors
        text = f"{result.method}: {result.timings.get('total', 0):.2f} s"
        if errors is not None:
            known = errors[np.isfinite(errors)]
            text += f", mean geodesic error {known.mean():.4f}, {100 * np.mean(known <= 0.05):.1f} % within 0.05"
        self.info.setText(text)
        self.redraw()

    def redraw(self, *_args) -> None:
        p = self.plotter
        p.clear_actors()
        self.target_colors = None
        if self.source is None or self.target is None:
            p.render()
            return
        mode = self.mode.currentText()
        src = polydata(self.source.vertices, self.source.faces)
        tgt = polydata(self.target.vertices, self.target.faces)
        map_yx = None if self.result is None else self.result.map_yx
        p.subplot(0, 0)
        p.add_text(f"source: {self.source.name}", font_size=9)
        if mode == "texture":
            tex = pv.numpy_to_texture(checkerboard())
            uv = cylindrical_uv(self.source.vertices)
            src.active_texture_coordinates = uv
            p.add_mesh(src, texture=tex)
            p.subplot(0, 1)
            if map_yx is not None:
                tgt.active_texture_coordinates = uv[np.clip(map_yx, 0, None)]
                p.add_mesh(tgt, texture=tex)
            else:
                p.add_mesh(tgt, color="lightgrey")
        elif mode == "error" and self.errors is not None:
            src["error"] = self.errors
            p.add_mesh(src, scalars="error", cmap="inferno", clim=(0, 0.15), nan_color="lightgrey",
                       scalar_bar_args={"title": "geodesic error / sqrt(area)"})
            p.subplot(0, 1)
            p.add_mesh(tgt, color="lightgrey")
        else:
            colors = coordinate_colors(self.source.vertices)
            p.add_mesh(src, scalars=colors, rgb=True)
            p.subplot(0, 1)
            if map_yx is not None:
                self.target_colors = np.where((map_yx >= 0)[:, None], colors[np.clip(map_yx, 0, None)], 0.7)
                p.add_mesh(tgt, scalars=self.target_colors, rgb=True)
            else:
                p.add_mesh(tgt, color="lightgrey")
            if mode == "error":
                self.info.setText("No ground truth loaded: File > Load ground truth (.vts) to see errors.")
        p.add_text(f"target: {self.target.name}", font_size=9)
        p.link_views()
        p.reset_camera()
        p.render()

    def close_plotters(self) -> None:
        self.plotter.close()
