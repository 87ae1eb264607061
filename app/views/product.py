"""Product view: a 2D-to-3D match (contour and mesh with the matched closed curve, coloured by position), or two
contours matched on their product torus (the contours' correspondence above, the 3D and the flat torus below)."""

from __future__ import annotations

import numpy as np
from PySide6.QtWidgets import QComboBox, QHBoxLayout, QLabel, QVBoxLayout, QWidget

from app.views.camera import (DISPLAY_FRAME, FramedView, RefitOnResize, ShapeDisplay, current_camera, show_preset,
                              window_size)
from app.views.scene import (PLAIN_COLOR, UNMATCHED_GREY, LazyPlotter, add_caption, hue_colors, lifted_curve,
                             outward_normals, polydata, polyline)
from corrlib.viewing import ViewFrame, outline_frame

CURVE_WIDTH = 4  # line width of the query contour
#: what the Product tab says before a match
PRODUCT_HINT = ("Match a contour to a mesh (2D-to-3D) to see the matched curve here. Product-torus views of contour "
                "pairs appear when that method is available.")
CURVE_TUBE_RADIUS = 0.007  # radius of the matched curve's tube, relative to the mesh's bounding-box diagonal
#: viewports (x0, y0, x1, y1) of the contour and of the mesh: side by side, or the contour above the mesh
SIDE_BY_SIDE = ((0.0, 0.0, 0.5, 1.0), (0.5, 0.0, 1.0, 1.0))
STACKED = ((0.0, 0.5, 1.0, 1.0), (0.0, 0.0, 1.0, 0.5))
#: viewports of a contour pair: the two contours and their correspondence above, the 3D and the flat torus below
CONTOUR_PAIR = ((0.0, 0.45, 1.0, 1.0), (0.0, 0.0, 0.5, 0.45), (0.5, 0.0, 1.0, 0.45))
#: the viewport of a view a layout does not use
HIDDEN = (0.0, 0.0, 0.0, 0.0)
#: corresponding points joined by a line in the contour pair's view (evenly spaced on contour A)
CORRESPONDENCE_LINES = 16


def drawn_scale(extent: tuple[float, float], viewport: tuple[float, float]) -> float:
    """Pixels per unit at which a shape of ``extent`` (width, height) just fits a ``viewport`` (width, height)."""
    return min(viewport[0] / max(extent[0], 1e-12), viewport[1] / max(extent[1], 1e-12))


def product_layout(extents: list[tuple[float, float]], window: tuple[float, float]) -> tuple:
    """:data:`SIDE_BY_SIDE` or :data:`STACKED`, whichever draws the contour and the mesh larger.

    Each shape's size is its :func:`drawn_scale` relative to its own larger extent, and the layout whose smaller
    shape is drawn larger wins (side by side on a tie): two wide shapes (an animal seen from the side) are
    stacked in a squarish window and drawn about twice as large, two tall ones (a person) stand side by side.

    Parameters
    ----------
    extents : list of (width, height)
        The contour's and the mesh's extents as shown.
    window : (width, height)
        The plot's size in pixels.
    """
    def smaller_size(viewports) -> float:
        return min(drawn_scale(extent, (window[0] * (x1 - x0), window[1] * (y1 - y0))) * max(extent)
                   for extent, (x0, y0, x1, y1) in zip(extents, viewports))

    return STACKED if smaller_size(STACKED) > smaller_size(SIDE_BY_SIDE) else SIDE_BY_SIDE


#: the 3D torus seen obliquely from above (VTK's isometric direction), its axis up on the screen
TORUS_FRAME = ViewFrame(np.array([-1.0, 1.0, 0.0]) / np.sqrt(2), np.array([-1.0, -1.0, 2.0]) / np.sqrt(6),
                        np.array([1.0, 1.0, 1.0]) / np.sqrt(3))
#: the flat torus' colour bar: three labels at a fixed small size (labels scaled with the bar ran into each
#: other and into the title in a laptop's window); the title is the function's name, shown above the view
TORUS_BAR = {"title": "", "fmt": "%.3g", "n_labels": 3, "unconstrained_font_size": True, "label_font_size": 12,
             "height": 0.06, "position_y": 0.04, "position_x": 0.15, "width": 0.7}  # end labels kept inside
#: the band below the flat square kept for that bar, in units of the square's side: the square is fitted together
#: with a point this far below it, so that the bar and its labels are drawn under the square, not over it
TORUS_BAR_BAND = 0.25


class ProductView(QWidget, FramedView):
    """A 2D-to-3D match: the query contour and the mesh with the matched curve (side by side or stacked), both
    coloured by contour position. Two contours: their correspondence above the 3D and the flat product torus."""

    def __init__(self, parent=None):
        super().__init__(parent)
        self.info = QLabel(PRODUCT_HINT)
        self.info.setWordWrap(True)
        self.function = QComboBox()
        self.function.setToolTip("Product function drawn on the torus (what the method provides: cost, "
                                 "densities, basis functions)")
        self.function.currentTextChanged.connect(self._redraw_pair)
        top = QHBoxLayout()
        top.addWidget(self.info, 1)
        self.function.setSizeAdjustPolicy(QComboBox.AdjustToContents)  # "harmonic_1", not "harmonic"
        self.function_label = QLabel("function")
        top.addWidget(self.function_label)
        top.addWidget(self.function)
        layout = QVBoxLayout(self)
        layout.addLayout(top)
        plot_box = QVBoxLayout()
        layout.addLayout(plot_box, 1)
        self._plotter = LazyPlotter(self, plot_box, shape=(1, 3))
        self._offer_functions([])
        self.curve = None  # the matched curve's polydata (for tests)
        self.torus_curve = None  # the correspondence curve on the torus (for tests)
        self.contours_shown = None  # a contour pair's two contours as drawn beside each other, (m + n, 3)
        self._pair = None
        self._match = None  # the arguments of the last show_contour_match (redrawn on a new up axis)
        self._contour_display: np.ndarray | None = None  # the query contour's points as drawn, (m, 3)
        self.mesh_points: np.ndarray | None = None  # the matched mesh in its display frame
        self.drawn_frame = None  # the upright view the matched curve looks most like the query from (ViewFrame)
        self._pair_views: list = []  # (points, frame) of a contour pair's three views, fitted to their viewports
        self._torus_cameras: list = []  # the cameras of that fit (a camera the user moved is not fitted again)
        self._torus_refit = None

    def clear(self) -> None:
        """Forget the last match or contour pair (the inputs changed: it belongs to the previous pair)."""
        if self._match is None and self._pair is None:
            return
        self._match = self._pair = None
        self.mesh_points = self.drawn_frame = self.curve = self.torus_curve = self.contours_shown = None
        self._offer_functions([])
        self.plotter.clear_actors()
        self.plotter.render()
        self.info.setText(PRODUCT_HINT)

    def view_plotter(self):
        return self._plotter.get() if self.mesh_points is not None else None

    def framed_points(self) -> list[np.ndarray]:
        return [] if self.mesh_points is None else [self.mesh_points]

    def framed_renderers(self):
        return [self.plotter.renderers[1]]  # the mesh; the contour keeps its 2D view

    def redraw(self) -> None:
        if self._match is not None:
            self._draw_contour_match(*self._match)

    @property
    def default_view(self) -> str:
        return "drawn" if self.drawn_frame is not None else "front"

    def preset_frame(self):
        """``"drawn"``: the mesh seen from the upright view (front, back, a side or the top) from which the matched
        curve looks most like the query (:func:`corrlib.viewing.outline_frame`), where the whole curve is in
        sight; a preset view can show the curve behind the shape."""
        if self.view == "drawn" and self.drawn_frame is not None:
            return self.drawn_frame, "front"
        return super().preset_frame()

    @property
    def plotter(self):
        return self._plotter.get()

    def show_contour_match(self, contour_points: np.ndarray, mesh, path_vertices: np.ndarray,
                           path_contour_index: np.ndarray, energy: float) -> None:
        """A new 2D-to-3D match, the mesh seen as drawn (:meth:`preset_frame`)."""
        self.view = "drawn"
        self._draw_contour_match(contour_points, mesh, path_vertices, path_contour_index, energy)

    def _draw_contour_match(self, contour_points: np.ndarray, mesh, path_vertices: np.ndarray,
                            path_contour_index: np.ndarray, energy: float) -> None:
        self._match = (contour_points, mesh, path_vertices, path_contour_index, energy)
        self._pair, self._pair_views, self.contours_shown = None, [], None  # no torus to fit again
        p = self.plotter
        p.clear_actors()
        m = contour_points.shape[0]
        p.subplot(0, 0)
        line = polyline(contour_points)
        line["position"] = np.arange(m) / m
        p.add_mesh(line, scalars=hue_colors(np.arange(m) / m), rgb=True, line_width=CURVE_WIDTH)
        add_caption(p, "query contour")
        p.subplot(0, 1)
        display = ShapeDisplay.of(mesh.vertices, self.up)
        self.mesh_points = display.points(mesh.vertices)
        p.add_mesh(polydata(self.mesh_points, mesh.faces), color=PLAIN_COLOR, smooth_shading=True)
        self.curve = lifted_curve(self.mesh_points, display.directions(outward_normals(mesh)), path_vertices,
                                  CURVE_TUBE_RADIUS, closed=False)
        self.curve["colors"] = hue_colors(path_contour_index / m)  # carried onto the tube's points
        tube = self.curve.tube(radius=CURVE_TUBE_RADIUS)  # the display frame has unit diagonal
        if tube.n_points:
            p.add_mesh(tube, scalars="colors", rgb=True)
        else:  # a curve without length (every step on one vertex): its vertices, as points
            p.add_points(self.mesh_points[np.unique(path_vertices)], color="red", point_size=12,
                         render_points_as_spheres=True)
        add_caption(p, f"matched curve, energy {energy:.4g}: {mesh.name}")  # the name may be elided
        self.drawn_frame = None
        if np.unique(path_vertices).size > 2:
            self.drawn_frame = outline_frame(self.mesh_points[path_vertices], contour_points[path_contour_index],
                                             DISPLAY_FRAME)
        self._contour_display = np.asarray(line.points)
        self._lay_out_match()
        self.fit_preset()
        p.subplot(0, 0)
        self._fit_contour(self._contour_display)
        p.render()
        self.info.setText(f"{m} contour points matched along a closed curve of {len(path_vertices)} steps.")

    def _lay_out_match(self) -> None:
        """The contour and the mesh side by side or one above the other (:func:`product_layout`), the mesh's
        extent as seen from its preset frame."""
        frame = (self.drawn_frame or DISPLAY_FRAME).matrix[:2]
        seen = self.mesh_points @ frame.T
        extents = [tuple(np.ptp(points[:, :2], axis=0)) for points in (self._contour_display, seen)]
        self._set_viewports(product_layout(extents, window_size(self.plotter)))

    def _set_viewports(self, viewports) -> None:
        """The layout's viewports; views it does not name are hidden."""
        for i, renderer in enumerate(self.plotter.renderers):
            renderer.SetViewport(*(viewports[i] if i < len(viewports) else HIDDEN))

    def _on_resized(self) -> None:
        """Lay the match out again for the new size, and refit the mesh (while at its preset) and the contour to
        their viewports."""
        shown = self._match is not None and self._contour_display is not None
        if shown:
            self._lay_out_match()
        super()._on_resized()
        if shown:
            self.plotter.subplot(0, 0)
            self._fit_contour(self._contour_display)
            self.plotter.render()

    def _fit_contour(self, points: np.ndarray) -> None:
        """The contour seen from +z, fitted to its viewport below the caption's band like a mesh at its front
        preset (:func:`~app.views.camera.show_preset`). The fit takes the widget's own size: VTK's reset fits a
        bounding sphere to the window size it last rendered at, which lags a resize (too near) and, once it
        knows a narrow viewport, divides by its aspect (the contour at half its size)."""
        show_preset(self.plotter, [points], "front", [self.plotter.renderers[0]])

    def show_contour_pair(self, result) -> None:
        """Two contours: their point correspondence, the product torus (3D) and the flat square, with the
        correspondence curve."""
        names = list(result.path.product_functions)
        self._pair = result
        self._match, self.mesh_points, self.drawn_frame = None, None, None  # no mesh: no presets on the torus
        self._offer_functions(names)
        self._redraw_pair()

    def _offer_functions(self, names: list[str]) -> None:
        """The torus' product functions in the box (shown only where there are some: a 2D-to-3D match has
        none), without drawing."""
        self.function.blockSignals(True)
        self.function.clear()
        self.function.addItems(names)
        self.function.blockSignals(False)
        self.function.setVisible(bool(names))
        self.function_label.setVisible(bool(names))

    def _redraw_pair(self, *_args) -> None:
        from corrlib.geometry.torus import arclength_angles, path_angles, torus_embedding, torus_grid

        result = self._pair
        if result is None:
            return
        path = result.path
        u = arclength_angles(path.contour_points)
        v = arclength_angles(path.target_points)
        name = self.function.currentText()
        values = np.asarray(path.product_functions[name], dtype=np.float64).ravel() if name else None
        p = self.plotter
        p.clear_actors()
        for title in list(p.scalar_bars.keys()):  # bars are kept by title, and every function's bar has none
            p.remove_scalar_bar(title)
        self._set_viewports(CONTOUR_PAIR)
        p.subplot(0, 0)
        self.contours_shown = self._draw_contour_correspondence(path.contour_points, path.target_points, result)
        self._pair_views = [(self.contours_shown, DISPLAY_FRAME)]
        curve_uv = path_angles(path.layers, path.vertices, u, v)
        for col, flat in ((1, False), (2, True)):
            p.subplot(0, col)
            verts, faces, index = torus_grid(u, v, flat=flat)
            grid = polydata(verts, faces)
            if values is not None:
                grid[name] = values[index]
                p.add_mesh(grid, scalars=name, cmap="viridis", show_scalar_bar=flat,
                           scalar_bar_args=TORUS_BAR, opacity=1.0 if flat else 0.75)
            else:
                p.add_mesh(grid, color="lightgrey", opacity=1.0 if flat else 0.75)
            if flat:
                pts = np.column_stack([curve_uv[:, 0], np.mod(curve_uv[:, 1], 1.0), np.full(len(curve_uv), 0.01)])
                # break the drawn curve where it wraps across the seam of the square
                cut = np.flatnonzero(np.abs(np.diff(pts[:, 1])) > 0.5) + 1
                for piece in np.split(pts, cut):
                    if len(piece) > 1:
                        p.add_mesh(polyline(piece, closed=False), color="crimson", line_width=4)
                coloured = f": {name}" if values is not None else ""
                add_caption(p, f"flat torus A × B{coloured}")
            else:
                pts = torus_embedding(curve_uv[:, 0], curve_uv[:, 1], 1.0, 0.41)
                self.torus_curve = polyline(pts, closed=False)
                p.add_mesh(self.torus_curve.tube(radius=0.015), color="crimson")
                add_caption(p, "product torus A × B")
            shown = np.vstack([verts, [[0.5, -TORUS_BAR_BAND, 0.0]]]) if flat and values is not None else verts
            self._pair_views.append((shown, DISPLAY_FRAME if flat else TORUS_FRAME))
        self._fit_torus()
        p.render()
        self.info.setText(f"{len(u)} × {len(v)} product torus; correspondence energy {result.energy:.4g}")

    def _draw_contour_correspondence(self, points_a: np.ndarray, points_b: np.ndarray, result) -> np.ndarray:
        """Contour A coloured by its position, B beside it (mirrored where its partners face the other way,
        :func:`~corrlib.viewing.contours_side_by_side`) in the colour of its matched point of A (grey where
        unmatched), and lines between :data:`CORRESPONDENCE_LINES` points of A and their partners. Returns the
        points drawn, (m + n, 3)."""
        from corrlib.viewing import contours_side_by_side

        p = self.plotter
        *shown, mirrored = contours_side_by_side(points_a, points_b, result.map_xy)
        shown_a, shown_b = (np.column_stack([c, np.zeros(len(c))]) for c in shown)
        m = len(points_a)
        hue = hue_colors(np.arange(m) / m)
        colours_b = np.where((result.map_yx >= 0)[:, None], hue[np.maximum(result.map_yx, 0)], UNMATCHED_GREY)
        for points, colours in ((shown_a, hue), (shown_b, colours_b)):
            p.add_mesh(polyline(points), scalars=colours, rgb=True, line_width=CURVE_WIDTH)
        rows = np.linspace(0, m, CORRESPONDENCE_LINES, endpoint=False).astype(np.int64)
        rows = rows[result.map_xy[rows] >= 0]
        ends = np.stack([shown_a[rows], shown_b[result.map_xy[rows]]], axis=1).reshape(-1, 3)
        p.add_lines(ends, color="darkgrey", width=1)
        add_caption(p, "A and B" + (" (mirrored)" if mirrored else "") + ", coloured by the position on A")
        return np.vstack([shown_a, shown_b])

    def _fit_torus(self) -> None:
        """Each view of a contour pair (the contours, the torus, the square) fitted to its viewport's own size and
        shape, and again after every resize while its camera is where the fit put it. VTK's reset fits a bounding
        sphere to the height of the size it last rendered at: the widget is 100 × 30 pixels when a first result
        arrives, and a narrow viewport cut the square and the torus at the sides."""
        p = self.plotter
        for renderer, (points, frame) in zip(p.renderers, self._pair_views):
            show_preset(p, [points], "front", [renderer], frame)
        self._torus_cameras = [current_camera(p, renderer) for renderer in p.renderers]
        if self._torus_refit is None or self._torus_refit.plotter is not p:
            self._torus_refit = RefitOnResize(p, self._on_torus_resized)

    def _on_torus_resized(self) -> None:
        if self._pair is None or not self._pair_views:
            return
        p = self.plotter
        if all(np.allclose(current_camera(p, r).position, c.position) for r, c in zip(p.renderers,
                                                                                       self._torus_cameras)):
            self._fit_torus()
            p.render()

    def close_plotters(self) -> None:
        self._plotter.close()
