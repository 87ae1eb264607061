"""Pair view: source and target side by side with linked cameras, coloured through the map."""

from __future__ import annotations

import numpy as np
import pyvista as pv
from PySide6.QtCore import Signal
from PySide6.QtWidgets import QComboBox, QHBoxLayout, QLabel, QVBoxLayout, QWidget

from app.views.camera import Displayed, FramedView, enable_hover, picked_vertex
from app.views.scene import (
    ERROR_BAR_TITLE,
    ERROR_COLOR_MAX,
    PLAIN_COLOR,
    UNMATCHED_GREY,
    add_caption,
    close_plotter,
    coordinate_colors,
    make_plotter,
    polydata,
    transfer_colors,
)
from corrlib.geometry.uv import checkerboard, cylindrical_uv
from corrlib.shapes import TriMesh

MODES = ("coordinates", "function", "texture", "lines", "error")
N_LINES = 12  # correspondence lines drawn before the user picks more
ERROR_WITHIN = 0.05  # the info line gives the share of errors up to this
LINES_GAP = 0.25  # lines mode: space between source and target, in display units (bounding-box diagonals)
LINE_WIDTH = 2
POINT_SIZE = 12


class PairView(QWidget, FramedView):
    """Colour transfer (``colors_Y = colors_X[map_yx]``), texture transfer and error heat map.

    Nothing here computes more than colours: the errors and the source function
    arrive with the result (computed in the method's job, :func:`app.jobs.method_job`).
    Unmatched vertices (-1 in a map) are drawn grey and have no error.
    The mouse resting on a shape shows the vertex under it (:attr:`hovered`).
    """

    hovered = Signal(str)  # "vertex i of the source (name)"

    def __init__(self, parent=None):
        super().__init__(parent)
        self.plotter = make_plotter(self, shape=(1, 2))
        # side by side; the lines mode gives the first renderer the whole width (both shapes in one scene)
        self.split_viewports = [r.GetViewport() for r in self.plotter.renderers]
        self.mode = QComboBox()
        self.mode.addItems(MODES)
        self.mode.setToolTip("coordinates: source coloured by position; function: by its second Laplace-"
                             "Beltrami eigenfunction; texture: a checkerboard (or File > Texture image) on a "
                             "cylindrical UV map of the source; lines: both shapes in one scene with lines "
                             "between a few points and their partners (click the source to add points); "
                             "error: geodesic error (ground truth needed)")
        self.mode.currentTextChanged.connect(self.redraw)
        self.info = QLabel("Load a source and a target mesh, then run a method.")
        self.info.setWordWrap(True)  # a long result line (unmatched vertices) wraps instead of widening the window
        top = QHBoxLayout()
        top.addWidget(QLabel("Show"))
        top.addWidget(self.mode)
        top.addWidget(self.info, 1)
        layout = QVBoxLayout(self)
        layout.addLayout(top)
        layout.addWidget(self.plotter.interactor, 1)
        self.source = self.target = None
        self.absent: dict[str, str] = {}  # what stands where a mesh of the pair is not (set_shapes)
        self.result = None
        self.errors = None  # (n_x,) per-vertex errors of the source, NaN where unknown or unmatched
        self.function = None  # (n_x,) source function of the "function" mode (from the method's job)
        self.n_unmatched = 0  # source vertices the map leaves unmatched
        self.target_colors: np.ndarray | None = None
        self.texture_image = checkerboard()
        self.picked: list[int] = []  # source vertices with correspondence lines
        self.lines = None  # the polydata of the correspondence lines (for tests)
        self.displayed: Displayed | None = None  # source and target in their display frames
        self.shown_points: list[np.ndarray] = []  # display points of what is drawn (camera fitting)
        enable_hover(self.plotter, self._hover_text, self.hovered.emit)

    def set_shapes(self, source, target) -> None:
        """The inputs of the pair: the meshes are drawn (either alone until the other comes); a contour (None if
        nothing is loaded) is named, its match being the Product tab's."""
        inputs = {"source": source, "target": target}
        self.source, self.target = (shape if isinstance(shape, TriMesh) else None for shape in (source, target))
        self.result, self.errors, self.function, self.n_unmatched = None, None, None, 0
        self.picked = []
        self.absent = {which: "none loaded" if shape is None else "a contour (Product tab)"
                       for which, shape in inputs.items() if not isinstance(shape, TriMesh)}
        contours = [which for which, shape in inputs.items() if shape is not None and which in self.absent]
        if not self.absent:
            self.info.setText("Run a method to see the correspondence.")
        elif len(contours) == 2:
            self.info.setText("Both inputs are contours: their correspondence is shown in the Product tab.")
        elif contours == ["target"] and self.source is not None:
            self.info.setText("The target is a contour: a 2D-to-3D match takes the contour as the source.")
        elif contours:
            self.info.setText(f"The {contours[0]} is a contour: a 2D-to-3D match is shown in the Product tab.")
        else:
            self.info.setText(f"Load a {' and a '.join(self.absent)} mesh, then run a method.")
        self.redraw()

    def set_result(self, result, errors: np.ndarray | None = None, *, function: np.ndarray | None = None,
                   n_unmatched: int = 0) -> None:
        """Show ``result``.

        Parameters
        ----------
        errors : (n_x,) float, optional
            Geodesic error per source vertex, NaN where unknown or unmatched.
        function : (n_x,) float, optional
            The source function the "function" mode transfers.
        n_unmatched : int
            Source vertices the map leaves unmatched (reported, drawn grey).
        """
        self.result, self.errors, self.function, self.n_unmatched = result, errors, function, n_unmatched
        seconds = result.timings.get("total")  # none for a map read from a file
        text = result.method + ("" if seconds is None else f": {seconds:.2f} s")
        if errors is not None:
            known = errors[np.isfinite(errors)]
            text += (f", mean geodesic error {known.mean():.4f}, {100 * np.mean(known <= ERROR_WITHIN):.1f} % "
                     f"within {ERROR_WITHIN}" if known.size else ", no ground-truth vertex is matched")
        if n_unmatched:
            text += f"; {n_unmatched} source vertices unmatched (grey, left out of the error)"
        if errors is not None and result.map_xy is not None and len(result.map_xy) == len(errors):
            unknown = int(np.count_nonzero(~np.isfinite(errors) & (np.asarray(result.map_xy) >= 0)))
            text += f"; {unknown} vertices without ground truth (grey in the heat map)" if unknown else ""
        self.info.setText(text)
        self.redraw()

    def framed_points(self) -> list[np.ndarray]:
        return self.shown_points

    def _hover_text(self, renderer, point) -> str | None:
        """The vertex under the mouse: of the shape drawn in that subplot (lines mode: the nearer shape)."""
        if len(self.shown_points) != 2:
            return None
        renderers = list(self.plotter.renderers)
        lines = self.mode.currentText() == "lines"
        candidates = (0, 1) if lines else ((renderers.index(renderer),) if renderer in renderers else ())
        best = None
        for which in candidates:
            vertex = picked_vertex(self.shown_points[which], point)
            distance = np.linalg.norm(self.shown_points[which][vertex] - point)
            if best is None or distance < best[0]:
                best = (distance, which, vertex)
        if best is None:
            return None
        _, which, vertex = best
        shape = (self.source, self.target)[which]
        return f"vertex {vertex} of the {('source', 'target')[which]} ({shape.name})"

    def redraw(self, *_args) -> None:
        p = self.plotter
        p.clear_actors()
        self.target_colors = None
        self.shown_points = []
        if self.source is None or self.target is None:
            self._draw_alone()
            return
        mode = self.mode.currentText()
        self.displayed = Displayed.of((self.source, self.target), self.up, reuse=self.displayed)
        src_points, tgt_points = self.displayed.points
        src = polydata(src_points, self.source.faces)
        tgt = polydata(tgt_points, self.target.faces)
        lines = mode == "lines"
        for renderer, viewport in zip(p.renderers, self.split_viewports):
            renderer.SetViewport(*((0.0, 0.0, 1.0, 1.0) if lines and renderer is p.renderers[0] else
                                   (1.0, 0.0, 1.0, 1.0) if lines else viewport))
        if lines:
            self._draw_lines(src, tgt)
            return
        p.subplot(0, 0)
        add_caption(p, f"source: {self.source.name}")
        if mode == "texture":
            self._draw_texture(src, tgt_points)
        elif mode == "error" and self.errors is not None:
            self._draw_errors(src, tgt)
        else:
            self._draw_colors(src, tgt, mode)
        add_caption(p, f"target: {self.target.name}")
        p.link_views()
        self.shown_points = [src_points, tgt_points]
        self.fit_preset()
        p.render()

    def _draw_alone(self) -> None:
        """Before the pair is complete: the mesh loaded so far in its half of the view (the user sees what was
        loaded, and what a repair or the up axis made of it, before loading the other)."""
        p = self.plotter
        halves = [(index, which, shape) for index, (which, shape) in
                  enumerate((("source", self.source), ("target", self.target))) if shape is not None]
        if not halves:
            p.render()
            return
        for renderer, viewport in zip(p.renderers, self.split_viewports):
            renderer.SetViewport(*viewport)
        self.displayed = Displayed.of([shape for _, _, shape in halves], self.up, reuse=self.displayed)
        for (index, which, shape), points in zip(halves, self.displayed.points):
            p.subplot(0, index)
            add_caption(p, f"{which}: {shape.name}")
            p.add_mesh(polydata(points, shape.faces), color=PLAIN_COLOR)
        if len(halves) == 1:
            p.subplot(0, 1 - halves[0][0])
            other = ("source", "target")[1 - halves[0][0]]
            add_caption(p, f"{other}: {self.absent.get(other, 'none loaded')}")
        p.link_views()
        self.shown_points = list(self.displayed.points)
        self.fit_preset()
        p.render()

    def _map_yx(self) -> np.ndarray | None:
        return None if self.result is None else self.result.map_yx

    def _draw_texture(self, src, tgt_points: np.ndarray) -> None:
        """Texture on the source's cylindrical UV map; the target's matched faces carry it, the others are grey."""
        p = self.plotter
        tex = pv.numpy_to_texture(self.texture_image)
        uv = cylindrical_uv(self.source.vertices)
        src.active_texture_coordinates = uv
        p.add_mesh(src, texture=tex)
        p.subplot(0, 1)
        map_yx = self._map_yx()
        if map_yx is None:
            p.add_mesh(polydata(tgt_points, self.target.faces), color=PLAIN_COLOR)
            return
        matched = map_yx >= 0
        uv_y = np.zeros((self.target.n_vertices, 2))
        uv_y[matched] = uv[map_yx[matched]]
        textured = matched[self.target.faces].all(axis=1)  # faces with a partner at every corner
        if textured.any():
            mesh = polydata(tgt_points, self.target.faces[textured])
            mesh.active_texture_coordinates = uv_y
            p.add_mesh(mesh, texture=tex)
        if not textured.all():
            p.add_mesh(polydata(tgt_points, self.target.faces[~textured]), color=[UNMATCHED_GREY] * 3)

    def _draw_errors(self, src, tgt) -> None:
        p = self.plotter
        src["error"] = self.errors
        p.add_mesh(src, scalars="error", cmap="inferno", clim=(0, ERROR_COLOR_MAX), nan_color=PLAIN_COLOR,
                   # three labels stay apart on a 1280-pixel screen, where five overlapped
                   scalar_bar_args={"title": ERROR_BAR_TITLE, "n_labels": 3, "fmt": "%.2f"})
        p.subplot(0, 1)
        p.add_mesh(tgt, color=PLAIN_COLOR)

    def _draw_colors(self, src, tgt, mode: str) -> None:
        """Coordinates or function colours on the source, transferred through the map (unmatched: grey)."""
        p = self.plotter
        colors = coordinate_colors(self.source.vertices) if mode != "function" else self._function_colors()
        if colors is None:
            p.add_mesh(src, color=PLAIN_COLOR)
            self.info.setText("The function (the source's second eigenfunction) comes with a result: run a method.")
        else:
            p.add_mesh(src, scalars=colors, rgb=True)
        p.subplot(0, 1)
        map_yx = self._map_yx()
        if map_yx is not None and colors is not None:
            self.target_colors = transfer_colors(colors, map_yx)
            p.add_mesh(tgt, scalars=self.target_colors, rgb=True)
        else:
            p.add_mesh(tgt, color=PLAIN_COLOR)
        if mode == "error":
            self.info.setText("No ground truth loaded: File > Load ground truth (.vts) to see errors.")

    def _function_colors(self) -> np.ndarray | None:
        """Colours of the source function computed with the result (None before a result)."""
        from matplotlib import cm

        if self.function is None:
            return None
        f = self.function
        scaled = (f - f.min()) / max(np.ptp(f), 1e-300)
        return cm.viridis(scaled)[:, :3]

    def _draw_lines(self, src, tgt) -> None:
        """Source and target side by side in one scene, lines from picked points to their partners."""
        from corrlib.geometry.sampling import farthest_point_sampling

        p = self.plotter
        p.subplot(0, 0)
        colors = coordinate_colors(self.source.vertices)
        p.add_mesh(src, scalars=colors, rgb=True, pickable=True)
        # the target to the right of the source (both in display frames, of unit size)
        shift = np.array([LINES_GAP + (np.ptp(src.points[:, 0]) + np.ptp(tgt.points[:, 0])) / 2, 0.0, 0.0])
        tgt.points = tgt.points + shift
        p.add_mesh(tgt, color=PLAIN_COLOR, pickable=False)
        map_xy = None if self.result is None else self.result.map_xy
        self.lines = None
        if map_xy is not None:
            if not self.picked:
                self.picked = list(farthest_point_sampling(self.source.vertices, min(N_LINES, self.source.n_vertices)))
            shown = [v for v in self.picked if map_xy[v] >= 0]  # an unmatched vertex has no partner to draw
            if shown:
                starts = src.points[shown]
                ends = tgt.points[map_xy[shown]]
                self.lines = pv.line_segments_from_points(np.column_stack([starts, ends]).reshape(-1, 3))
                p.add_mesh(self.lines, color="black", line_width=LINE_WIDTH)
                p.add_points(np.vstack([starts, ends]), scalars=np.vstack([colors[shown]] * 2), rgb=True,
                             point_size=POINT_SIZE, render_points_as_spheres=True)
        add_caption(p, "click the source to add a correspondence line")
        if not getattr(self, "_picking", False):
            p.enable_point_picking(callback=self._on_pick, show_message=False, use_picker=True,
                                   left_clicking=True, show_point=False)
            self._picking = True
        self.shown_points = [src.points, tgt.points]
        self.fit_preset()
        p.render()

    def _on_pick(self, point, *_args) -> None:
        if self.source is None or self.target is None or self.mode.currentText() != "lines" or point is None:
            return
        self.add_line(picked_vertex(self.displayed.points[0], point))

    def add_line(self, vertex: int) -> None:
        """Add a correspondence line from a source vertex (picked with the mouse)."""
        if vertex not in self.picked:
            self.picked.append(vertex)
        self.redraw()

    def close_plotters(self) -> None:
        close_plotter(self.plotter)
