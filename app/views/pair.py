"""Pair view: source and target side by side with linked cameras, coloured through the map."""

from __future__ import annotations

import numpy as np
import pyvista as pv
from PySide6.QtWidgets import QComboBox, QHBoxLayout, QLabel, QVBoxLayout, QWidget

from app.views.scene import coordinate_colors, polydata, make_plotter
from corrlib.geometry.uv import checkerboard, cylindrical_uv

MODES = ("coordinates", "function", "texture", "lines", "error")
N_LINES = 12


class PairView(QWidget):
    """Colour transfer (``colors_Y = colors_X[map_yx]``), texture transfer and error heat map."""

    def __init__(self, parent=None):
        super().__init__(parent)
        self.plotter = make_plotter(self, shape=(1, 2))
        self.mode = QComboBox()
        self.mode.addItems(MODES)
        self.mode.setToolTip("coordinates: source coloured by position; function: by its second Laplace-"
                             "Beltrami eigenfunction; texture: a checkerboard (or File > Texture image) on a "
                             "cylindrical UV map of the source; lines: both shapes in one scene with lines "
                             "between a few points and their partners (click the source to add points); "
                             "error: geodesic error (ground truth needed)")
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
        self.texture_image = checkerboard()
        self.picked: list[int] = []  # source vertices with correspondence lines
        self.lines = None  # the polydata of the correspondence lines (for tests)

    def set_shapes(self, source, target) -> None:
        self.source, self.target, self.result, self.errors = source, target, None, None
        self.picked = []
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
        if mode == "lines":
            self._draw_lines(src, tgt)
            return
        p.subplot(0, 0)
        p.add_text(f"source: {self.source.name}", font_size=9)
        if mode == "texture":
            tex = pv.numpy_to_texture(self.texture_image)
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
            colors = coordinate_colors(self.source.vertices) if mode != "function" else self._function_colors()
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

    def _function_colors(self) -> np.ndarray:
        """Colours of the source's second eigenfunction (a smooth function to transfer)."""
        from matplotlib import cm

        from corrlib.geometry.spectrum import mesh_spectrum

        fiedler = mesh_spectrum(self.source, 3).evecs[:, 1]
        scaled = (fiedler - fiedler.min()) / max(np.ptp(fiedler), 1e-300)
        return cm.viridis(scaled)[:, :3]

    def _draw_lines(self, src, tgt) -> None:
        """Source and target side by side in one scene, lines from picked points to their partners."""
        from corrlib.geometry.sampling import farthest_point_sampling

        p = self.plotter
        p.subplot(0, 0)
        colors = coordinate_colors(self.source.vertices)
        p.add_mesh(src, scalars=colors, rgb=True, pickable=True)
        p.reset_camera()
        # put the target to the right of the source as the camera sees it
        cam = p.camera
        right = np.cross(np.asarray(cam.focal_point) - np.asarray(cam.position), np.asarray(cam.up))
        right /= max(np.linalg.norm(right), 1e-300)
        width = max(self.source.bbox_diagonal, self.target.bbox_diagonal)
        shift = 0.9 * width * right + self.source.vertices.mean(axis=0) - self.target.vertices.mean(axis=0)
        tgt.points = tgt.points + shift
        p.add_mesh(tgt, color="lightgrey", pickable=False)
        map_xy = None if self.result is None else self.result.map_xy
        if map_xy is not None:
            if not self.picked:
                self.picked = list(farthest_point_sampling(self.source.vertices, min(N_LINES, self.source.n_vertices)))
            starts = self.source.vertices[self.picked]
            ends = self.target.vertices[np.clip(map_xy[self.picked], 0, None)] + shift
            self.lines = pv.line_segments_from_points(np.column_stack([starts, ends]).reshape(-1, 3))
            p.add_mesh(self.lines, color="black", line_width=2)
            p.add_points(np.vstack([starts, ends]), scalars=np.vstack([colors[self.picked]] * 2), rgb=True,
                         point_size=12, render_points_as_spheres=True)
        p.add_text("click the source to add a correspondence line", font_size=9)
        p.subplot(0, 1)
        p.add_text("(lines mode: both shapes on the left)", font_size=9)
        p.subplot(0, 0)
        if not getattr(self, "_picking", False):
            p.enable_point_picking(callback=self._on_pick, show_message=False, use_picker=True,
                                   left_clicking=True, show_point=False)
            self._picking = True
        p.reset_camera()
        p.render()

    def _on_pick(self, point, *_args) -> None:
        if self.source is None or self.mode.currentText() != "lines" or point is None:
            return
        vertex = int(np.argmin(np.linalg.norm(self.source.vertices - np.asarray(point), axis=1)))
        self.add_line(vertex)

    def add_line(self, vertex: int) -> None:
        """Add a correspondence line from a source vertex (picked with the mouse)."""
        if vertex not in self.picked:
            self.picked.append(vertex)
        self.redraw()

    def close_plotters(self) -> None:
        self.plotter.close()
