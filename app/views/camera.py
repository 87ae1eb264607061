"""Framing shared by the 3D views: shapes in their display frame, camera presets, cameras saved as JSON.

Every shape is drawn in its *display frame* (:class:`ShapeDisplay`): centred,
rotated so that its up axis is +y and its front view looks down −z
(:func:`corrlib.viewing.view_frame`), and scaled to unit bounding-box
diagonal. Shapes of different files, units and up conventions therefore
stand alike, and one camera (linked views) frames them all. The presets of
:data:`corrlib.viewing.VIEWS` fit the shapes tightly into each viewport.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from corrlib.viewing import Camera, ViewFrame, fitted_camera, view_frame

#: the display frame's own axes: right +x, up +y, toward the front camera +z
DISPLAY_FRAME = ViewFrame(np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]))
#: pixels at the top of a 3D view kept free of the shape for its one-line caption, and the largest share of a
#: (small) viewport's height they may take
CAPTION_BAND_PX = 24
MAX_CAPTION_BAND = 0.25


@dataclass(frozen=True)
class ShapeDisplay:
    """The similarity taking a shape's coordinates to its display frame.

    Attributes
    ----------
    centre : (3,) float
        Bounding-box centre of the shape.
    rotation : (3, 3) float
        Rows: the shape's right, up and toward axes (:class:`~corrlib.viewing.ViewFrame`).
    scale : float
        Bounding-box diagonal (display size 1).
    """

    centre: np.ndarray
    rotation: np.ndarray
    scale: float

    @classmethod
    def of(cls, vertices: np.ndarray, up: str = "auto") -> "ShapeDisplay":
        v = np.asarray(vertices, dtype=np.float64)
        lo, hi = v.min(axis=0), v.max(axis=0)
        return cls((lo + hi) / 2, view_frame(v, up).matrix, max(float(np.linalg.norm(hi - lo)), 1e-300))

    def points(self, vertices: np.ndarray) -> np.ndarray:
        """(n, 3) float: ``vertices`` (the shape's or its deformations') in the display frame."""
        return (np.asarray(vertices, dtype=np.float64) - self.centre) @ self.rotation.T / self.scale

    def directions(self, vectors: np.ndarray) -> np.ndarray:
        """(n, 3) float: unit ``vectors`` (e.g. normals) in the display frame (rotated; lengths kept)."""
        return np.asarray(vectors, dtype=np.float64) @ self.rotation.T


@dataclass(frozen=True)
class Displayed:
    """Shapes in their display frames, for one up-axis setting (computed once, reused by every redraw).

    Attributes
    ----------
    shapes : tuple of TriMesh
    up : str
    displays : tuple of ShapeDisplay
    points : tuple of (n_i, 3) float
        Every shape's vertices in its display frame.
    """

    shapes: tuple
    up: str
    displays: tuple
    points: tuple

    @classmethod
    def of(cls, shapes, up: str = "auto", reuse: "Displayed | None" = None) -> "Displayed":
        """The shapes' display frames; ``reuse`` is returned instead when it holds the same shapes and up axis."""
        shapes = tuple(shapes)
        if reuse is not None and reuse.up == up and len(reuse.shapes) == len(shapes) \
                and all(a is b for a, b in zip(reuse.shapes, shapes)):
            return reuse
        displays = tuple(ShapeDisplay.of(shape.vertices, up) for shape in shapes)
        return cls(shapes, up, displays, tuple(d.points(shape.vertices) for d, shape in zip(displays, shapes)))


def viewport_aspect(plotter, renderer=None) -> float:
    """Width / height in pixels of a renderer's viewport (the first renderer by default).

    Taken from the Qt widget's size where there is one (the render window
    learns its new size only at its next render), else from the window size.
    """
    renderer = renderer or plotter.renderers[0]
    x0, y0, x1, y1 = renderer.GetViewport()
    width, height = window_size(plotter)
    return max((x1 - x0) * width, 1.0) / max((y1 - y0) * height, 1.0)


def caption_band(plotter, renderer) -> float:
    """The share of ``renderer``'s viewport height that its one-line caption (``add_text`` at the upper left, in
    :data:`~app.views.scene.CAPTION_FONT_PX`) takes: :data:`CAPTION_BAND_PX`, at most :data:`MAX_CAPTION_BAND`."""
    x0, y0, x1, y1 = renderer.GetViewport()
    height = max((y1 - y0) * window_size(plotter)[1], 1.0)
    return min(CAPTION_BAND_PX / height, MAX_CAPTION_BAND)


def window_size(plotter) -> tuple[int, int]:
    """Width and height in pixels of the plotter's whole window: the Qt widget's size where there is one (the
    render window learns its new size only at its next render), else the window size."""
    interactor = getattr(plotter, "interactor", None)
    if interactor is not None and hasattr(interactor, "width") and interactor.width() > 0:
        return interactor.width(), interactor.height()
    return tuple(plotter.window_size)


def apply_camera(plotter, camera: Camera, renderers=None) -> None:
    """Set the camera of ``renderers`` (default: every renderer of ``plotter``; linked views share one)."""
    for renderer in plotter.renderers if renderers is None else renderers:
        renderer.camera.position = camera.position
        renderer.camera.focal_point = camera.focal_point
        renderer.camera.up = camera.view_up
        renderer.camera.view_angle = camera.view_angle
        renderer.ResetCameraClippingRange()


def current_camera(plotter, renderer=None) -> Camera:
    """The camera of ``renderer`` (default: the first renderer of ``plotter``) as plain data."""
    cam = (renderer or plotter.renderers[0]).camera
    return Camera(tuple(map(float, cam.position)), tuple(map(float, cam.focal_point)), tuple(map(float, cam.up)),
                  float(cam.view_angle))


def show_preset(plotter, display_points: list[np.ndarray], view: str = "front", renderers=None,
                frame: ViewFrame = DISPLAY_FRAME) -> Camera:
    """Put the camera at the preset ``view`` of ``frame`` (default: the display frame's), fitted to the union of
    ``display_points``.

    Parameters
    ----------
    display_points : list of (n_i, 3) float
        The points shown, in display frames (every renderer shows one of them).
    renderers : list of vtkRenderer, optional
        The renderers to set (default: all of ``plotter``'s).
    frame : ViewFrame
        In display coordinates, e.g. the view a matched outline was drawn from
        (:func:`corrlib.viewing.outline_frame`).
    """
    points = np.vstack([np.asarray(p, dtype=np.float64) for p in display_points])
    first = plotter.renderers[0] if renderers is None else renderers[0]
    camera = fitted_camera(points, frame, view, aspect=viewport_aspect(plotter, first),
                           top=caption_band(plotter, first))
    apply_camera(plotter, camera, renderers)
    return camera


class FramedView:
    """What the View menu needs of a 3D view: an up-axis setting, presets, and its camera.

    A view sets ``self.up`` and ``self.view`` (the last preset) and implements
    :meth:`framed_points` (the display points it shows) and :meth:`redraw`.
    """

    up: str = "auto"
    view: str = "front"  # a preset of corrlib.viewing.VIEWS, or "drawn" (see preset_frame)

    def view_plotter(self):
        """The view's plotter, or None before it shows anything."""
        return getattr(self, "plotter", None)

    def framed_points(self) -> list[np.ndarray]:
        """The display points the view shows (every view defines it; empty: nothing shown yet)."""
        return []

    def framed_renderers(self):
        """The renderers the presets move (None: all of the plotter's)."""
        return None

    @property
    def default_view(self) -> str:
        """The view that Reset camera returns to."""
        return "front"

    def preset_frame(self) -> tuple[ViewFrame, str]:
        """The frame and the preset of it that :attr:`view` names. ``"drawn"`` (as a matched outline shows the
        shape) is the front view in views that show no outline."""
        return DISPLAY_FRAME, "front" if self.view == "drawn" else self.view

    def set_up_axis(self, up: str) -> None:
        """Draw again with another up-axis setting (``"auto"`` or ``"+x"`` … ``"-z"``)."""
        self.up = up
        self.redraw()

    def show_view(self, view: str) -> None:
        """Fit the camera to the preset ``view`` (front, side, top, or drawn: see :meth:`preset_frame`)."""
        self.view = view
        self.fit_preset()
        plotter = self.view_plotter()
        if plotter is not None:
            plotter.render()

    def fit_preset(self) -> None:
        """Put the camera at the current preset, fitted to what is shown; fitted again when the view is
        resized, until the user moves the camera."""
        plotter, points = self.view_plotter(), self.framed_points()
        if plotter is None or not points:
            return
        renderers = self.framed_renderers()
        frame, view = self.preset_frame()
        self._preset_camera = show_preset(plotter, points, view, renderers, frame)
        if getattr(self, "_refit_filter", None) is None or self._refit_filter.plotter is not plotter:
            self._refit_filter = RefitOnResize(plotter, self._on_resized)

    def _on_resized(self) -> None:
        plotter = self.view_plotter()
        preset = getattr(self, "_preset_camera", None)
        if plotter is None or preset is None or not self.framed_points():
            return
        renderers = self.framed_renderers()
        now = current_camera(plotter, None if renderers is None else renderers[0])
        if np.allclose(now.position, preset.position) and np.allclose(now.focal_point, preset.focal_point):
            self.fit_preset()
            plotter.render()

    def camera(self) -> Camera | None:
        plotter = self.view_plotter()
        if plotter is None or not self.framed_points():
            return None
        renderers = self.framed_renderers()
        return current_camera(plotter, None if renderers is None else renderers[0])

    def set_camera(self, camera: Camera) -> None:
        plotter = self.view_plotter()
        if plotter is not None and self.framed_points():
            apply_camera(plotter, camera, self.framed_renderers())
            plotter.render()


class RefitOnResize:
    """Calls ``callback`` after the plotter's widget is resized (a Qt event filter)."""

    def __init__(self, plotter, callback):
        from PySide6.QtCore import QEvent, QObject

        class Filter(QObject):
            def eventFilter(self, _obj, event):  # noqa: N802 (Qt's name)
                if event.type() == QEvent.Resize:
                    callback()
                return False

        self.plotter = plotter
        self.filter = Filter(plotter.interactor)
        plotter.interactor.installEventFilter(self.filter)


def picked_vertex(points: np.ndarray, point) -> int:
    """The index of the vertex of ``points`` (n, 3) nearest to a picked ``point`` (3,)."""
    return int(np.argmin(np.linalg.norm(np.asarray(points) - np.asarray(point, dtype=np.float64), axis=1)))


#: hover picking runs at most this often (seconds)
HOVER_INTERVAL = 0.05


def enable_hover(plotter, describe, show) -> None:
    """Call ``show(describe(renderer, point))`` when the mouse rests on a shape of ``plotter``.

    ``describe`` gets the renderer under the mouse and the picked world point
    and returns a text (or None for nothing to say). Picking runs at most
    every :data:`HOVER_INTERVAL` seconds.
    """
    import time

    from vtkmodules.vtkRenderingCore import vtkPointPicker

    picker = vtkPointPicker()
    picker.SetTolerance(0.005)
    last = [0.0]

    def on_move(interactor, _event):
        now = time.monotonic()
        if now - last[0] < HOVER_INTERVAL:
            return
        last[0] = now
        x, y = interactor.GetEventPosition()
        renderer = interactor.FindPokedRenderer(x, y)
        if renderer is None or not picker.Pick(x, y, 0, renderer) or picker.GetPointId() < 0:
            return
        text = describe(renderer, np.array(picker.GetPickPosition()))
        if text:
            show(text)

    plotter.iren.add_observer("MouseMoveEvent", on_move)
