"""Building pyvista objects from corrlib arrays (GUI thread only)."""

from __future__ import annotations

import numpy as np
import pyvista as pv

from corrlib.plotting import coordinate_colors  # noqa: F401  (re-exported for the views)

#: RGB grey of target vertices the map leaves unmatched (-1): neutral, never a transferred colour
UNMATCHED_GREY = 0.7
#: colour of a shape drawn without any data
PLAIN_COLOR = "lightgrey"
#: pixel height of a caption at the top left of a 3D view, the same in every view and window: VTK's corner
#: annotation scales its text with the viewport and shrinks a long line, so that two captions side by side
#: differed in size
CAPTION_FONT_PX = 13
#: the corner of VTK's corner annotation that holds a caption (vtkCornerAnnotation::UpperLeft)
UPPER_LEFT = 2
#: a caption character's mean advance in units of the font's pixel height (to shorten a caption to its view)
CAPTION_CHAR_WIDTH = 0.55
#: top of the error colour scale of every heat map (geodesic error / sqrt(area))
ERROR_COLOR_MAX = 0.15
#: the heat map's colour bar title: short enough for a half view at 1280 × 720
ERROR_BAR_TITLE = "error / √area"


def transfer_colors(colors: np.ndarray, map_yx: np.ndarray) -> np.ndarray:
    """(n_y, 3) ``colors[map_yx]``, :data:`UNMATCHED_GREY` where ``map_yx`` is -1 (unmatched)."""
    map_yx = np.asarray(map_yx)
    matched = map_yx >= 0
    out = np.full((map_yx.shape[0], colors.shape[1]), UNMATCHED_GREY, dtype=np.float64)
    out[matched] = colors[map_yx[matched]]
    return out


def polydata(vertices: np.ndarray, faces: np.ndarray) -> pv.PolyData:
    """A pyvista mesh with the given vertex order."""
    f = np.asarray(faces, dtype=np.int64)
    cells = np.column_stack([np.full(f.shape[0], 3), f]).ravel()
    return pv.PolyData(np.asarray(vertices, dtype=np.float64).copy(), cells)


def polyline(points: np.ndarray, closed: bool = True) -> pv.PolyData:
    """A line through ``points`` (n, 2 or 3)."""
    p = np.asarray(points, dtype=np.float64)
    if p.shape[1] == 2:
        p = np.column_stack([p, np.zeros(p.shape[0])])
    n = p.shape[0]
    idx = np.arange(n + 1 if closed else n) % n
    return pv.PolyData(p, lines=np.concatenate([[idx.size], idx]))


def outward_normals(mesh) -> np.ndarray:
    """(n, 3) float: the mesh's unit vertex normals, turned outward where a closed mesh's faces are oriented
    inward (negative enclosed volume); an open mesh's as its faces give them."""
    from corrlib.descriptors.orientation import outward_sign

    return outward_sign(mesh) * mesh.vertex_normals


def lifted_curve(points: np.ndarray, normals: np.ndarray, path_vertices: np.ndarray, lift: float,
                 closed: bool = True) -> pv.PolyData:
    """A curve through mesh vertices, lifted off the surface by ``lift`` along the outward vertex normals.

    Drawn as a tube of radius ``lift``, it lies on the surface instead of half inside it. A curve along the
    outline of the view (an animal's back or belly seen from the side, where a silhouette's curve runs) would
    otherwise be half hidden by the shape it lies on, and a thin tube entirely.

    Parameters
    ----------
    points, normals : (n, 3) float
        The mesh's vertices and outward unit vertex normals (:func:`outward_normals`), in one frame.
    path_vertices : (p,) int
        The curve's vertices in order.
    lift : float
        Distance from the surface, in the units of ``points``.
    closed : bool
        Whether the last vertex joins the first.
    """
    path = np.asarray(path_vertices)
    return polyline(points[path] + lift * normals[path], closed=closed)


def hue_colors(values: np.ndarray) -> np.ndarray:
    """(n, 3) RGB in [0, 1] from values in [0, 1) on the HSV hue circle."""
    from matplotlib import cm

    return cm.hsv(np.mod(values, 1.0))[:, :3]


def make_plotter(parent, **kwargs):
    """A QtInteractor that renders only when asked (no periodic auto-update timer).

    pyvistaqt's default re-renders every plotter five times per second; with
    several views under software OpenGL that alone can stall the GUI thread.
    """
    from pyvistaqt import QtInteractor

    return QtInteractor(parent, auto_update=False, **kwargs)


def close_plotter(plotter) -> None:
    """Close a QtInteractor and cut every Python callback Qt could still run for its widget.

    A closed plotter's widget lives on until Qt deletes it with its window (or a view replaces it), and Qt
    sends a widget events while it deletes it. Python code run from inside that C++ destructor chain is a
    known source of crashes, so none is left: the event filters that are the widget's children (ours, e.g.
    the camera's refit on resize) are removed, and VTK's connection of the parent's ``destroyed`` signal to
    the widget's ``close`` (already done here) is cut.
    """
    import warnings

    plotter.close()
    widget = plotter.interactor
    for child in widget.children():
        widget.removeEventFilter(child)  # a no-op for children that are no filter
    parent = widget.parent()
    if parent is not None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # PySide warns when nothing was connected
            try:
                parent.destroyed.disconnect(widget.close)
            except (RuntimeError, TypeError):
                pass


class LazyPlotter:
    """A view's plotter, created on first use (views on hidden tabs cost nothing at start-up).

    Parameters
    ----------
    parent : QWidget
    layout : QLayout
        Where the interactor widget goes once created (stretch 1).
    **kwargs
        Passed to :func:`make_plotter`.
    """

    def __init__(self, parent, layout, **kwargs):
        self._parent, self._layout, self._kwargs = parent, layout, kwargs
        self._plotter = None

    def get(self):
        if self._plotter is None:
            self._plotter = make_plotter(self._parent, **self._kwargs)
            self._layout.addWidget(self._plotter.interactor, 1)
        return self._plotter

    @property
    def created(self) -> bool:
        """Whether the plotter exists (asked before clearing one that was never shown)."""
        return self._plotter is not None

    def close(self) -> None:
        if self._plotter is not None:
            close_plotter(self._plotter)


def elided_caption(text: str, width_px: float, font_px: int = CAPTION_FONT_PX) -> str:
    """Each line of ``text`` cut to fit ``width_px`` pixels at ``font_px`` (an estimate from
    :data:`CAPTION_CHAR_WIDTH`), its end replaced by an ellipsis where it is cut: the start names the shape."""
    fits = max(int(width_px / (CAPTION_CHAR_WIDTH * font_px)) - 1, 2)  # a character's margin at the left edge
    return "\n".join(line if len(line) <= fits else line[:fits - 1].rstrip() + "…" for line in text.split("\n"))


def add_caption(plotter, text: str, font_px: int = CAPTION_FONT_PX):
    """Write ``text`` at the top left of the plotter's active view at ``font_px`` pixels, whatever the size of the
    view and the length of the line. Each line is shortened to the view's width (:func:`elided_caption`) as the
    view is rendered: a view's size is known only then (a new widget measures 100 × 30 before it is laid out).
    A view has one caption: the one it had is no longer fitted. Returns the actor."""
    renderer = plotter.renderer
    actor = plotter.add_text(text, position="upper_left", font_size=font_px)
    actor.SetMinimumFontSize(font_px)
    actor.SetMaximumFontSize(font_px)

    def fit_to_view(*_args):
        width = renderer.GetSize()[0]
        if width > 0:
            actor.SetText(UPPER_LEFT, elided_caption(text, width, font_px))

    # one caption per view: the observer of the caption it replaces goes (views are redrawn many times)
    previous = getattr(renderer, "_caption_observer", None)
    if previous is not None:
        renderer.RemoveObserver(previous)
    renderer._caption_observer = renderer.AddObserver("StartEvent", fit_to_view)  # pyvista allows _ names
    return actor
