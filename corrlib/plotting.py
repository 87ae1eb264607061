"""Static pictures with matplotlib (Agg): colour transfer, cumulative error curves.

Imported on demand only (``corrlib`` itself does not import matplotlib).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _figure(**kwargs):
    """A matplotlib ``Figure`` drawn off-screen by Agg, whatever backend the environment asks for (``MPLBACKEND``,
    a notebook's): no pyplot, no global state. matplotlib is imported with Ctrl-C and SIGTERM held back
    (:mod:`corrlib.interrupts`: an interrupt inside a compiled module's initialisation would be lost, and
    matplotlib would go on without its 3D axes)."""
    from corrlib.interrupts import signals_held

    with signals_held():
        _import_matplotlib()
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
        import mpl_toolkits.mplot3d  # noqa: F401  (registers the 3D projection)

    fig = Figure(**kwargs)
    FigureCanvasAgg(fig)
    return fig


def _import_matplotlib() -> None:
    """Import matplotlib; where ``MPLBACKEND`` names no backend (matplotlib refuses to import then), without it,
    with a warning: these pictures never use the backend."""
    import os
    import sys

    try:
        import matplotlib  # noqa: F401
    except ValueError:
        value = os.environ.pop("MPLBACKEND", None)
        if value is None:
            raise
        print(f"warning: MPLBACKEND={value!r} names no matplotlib backend; ignored (the pictures are drawn "
              "off-screen)", file=sys.stderr)
        for name in [name for name in sys.modules if name == "matplotlib" or name.startswith("matplotlib.")]:
            del sys.modules[name]  # what the failed import left half-initialised
        import matplotlib  # noqa: F401


def preload() -> None:
    """Import matplotlib and its off-screen canvas (about half a second), e.g. in a thread before pictures."""
    _figure()


def _save_figure(fig, path) -> Path:
    """Write a figure as PNG atomically."""
    from corrlib.io import atomic_write

    from matplotlib.text import Text

    for text in fig.findobj(Text):  # a file name that is not UTF-8 (its bytes as surrogates) shown by its bytes
        value = text.get_text()
        try:
            shown = value.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
        except UnicodeEncodeError:  # a surrogate that stands for no byte
            shown = value.encode("utf-8", "backslashreplace").decode("utf-8")
        if shown != value:
            text.set_text(shown)
    fig.tight_layout()
    path = Path(path)
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png")
    return path


def coordinate_colors(vertices: np.ndarray) -> np.ndarray:
    """(n, 3) float in [0, 1]: RGB from the vertex coordinates normalised to the bounding box."""
    v = np.asarray(vertices, dtype=np.float64)
    lo, hi = v.min(axis=0), v.max(axis=0)
    return np.clip((v - lo) / np.where(hi > lo, hi - lo, 1.0), 0.0, 1.0)


def view_axes(reference: np.ndarray, up: str = "auto") -> np.ndarray:
    """The viewing frame of the pictures: the front view of :mod:`corrlib.viewing` (the studio's framing).

    Parameters
    ----------
    reference : (n, 3) float
        The points whose up axis and horizontal principal axes orient the view.
    up : str
        Up-axis setting (``"auto"`` or ``"+x"`` … ``"-z"``).

    Returns
    -------
    (3, 3) float
        Rows: screen right as x, away from the viewer as y, up as z (a proper rotation; matplotlib's
        ``view_init(elev, azim=-90)`` looks along +y).
    """
    from corrlib.viewing import view_frame

    frame = view_frame(reference, up)
    return np.stack([frame.right, -frame.toward, frame.up])


def draw_mesh(ax, vertices: np.ndarray, faces: np.ndarray, colors: np.ndarray, title: str = "",
              frame_from: np.ndarray | None = None) -> None:
    """Draw a triangle mesh with per-vertex colours on a 3D matplotlib axis (flat face colours).

    ``frame_from`` gives the vertices whose principal axes orient the view
    (pass the source's to view two shapes alike).
    """
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    axes = view_axes(vertices if frame_from is None else frame_from)
    v = (vertices - vertices.mean(axis=0)) @ axes.T
    tris = v[faces]
    face_colors = np.asarray(colors)[faces].mean(axis=1)
    # simple Lambert shading towards the viewer for depth cues
    normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    light = np.array([0.3, -0.8, 0.5])
    shade = 0.55 + 0.45 * np.abs(normals @ (light / np.linalg.norm(light)))
    coll = Poly3DCollection(tris, facecolors=np.clip(face_colors * shade[:, None], 0, 1), linewidths=0)
    ax.add_collection3d(coll)
    span = (v.max(axis=0) - v.min(axis=0)).max() / 2
    mid = (v.max(axis=0) + v.min(axis=0)) / 2
    for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), mid):
        setter(c - span, c + span)
    ax.view_init(elev=10, azim=-90)
    ax.set_axis_off()
    ax.set_title(title)


def save_colour_transfer(path, source, target, map_yx: np.ndarray, *, source_colors=None, title: str = "") -> Path:
    """PNG with the source coloured by its coordinates and the target coloured through ``map_yx``.

    Parameters
    ----------
    path : str or Path
    source, target : TriMesh
    map_yx : (n_y,) int
        Source vertex of every target vertex (-1 = unmatched, drawn grey).
    source_colors : (n_x, 3) float, optional
    """
    colors_x = coordinate_colors(source.vertices) if source_colors is None else np.asarray(source_colors)
    map_yx = np.asarray(map_yx)
    colors_y = np.where((map_yx >= 0)[:, None], colors_x[np.clip(map_yx, 0, None)], 0.6)
    fig = _figure(figsize=(10, 5), dpi=100)
    ax1 = fig.add_subplot(1, 2, 1, projection="3d")
    ax2 = fig.add_subplot(1, 2, 2, projection="3d")
    draw_mesh(ax1, source.vertices, source.faces, colors_x, f"source: {source.name}")
    draw_mesh(ax2, target.vertices, target.faces, colors_y, f"target: {target.name} (colours through the map)",
              frame_from=target.vertices)
    if title:
        fig.suptitle(title)
    return _save_figure(fig, path)


def save_error_curves(path, curves: dict, thresholds: np.ndarray, *, title: str = "Cumulative geodesic error") -> Path:
    """PNG of cumulative error curves: ``curves`` maps a label to an array like ``thresholds``."""
    fig = _figure(figsize=(6, 4.5), dpi=100)
    ax = fig.subplots()
    for label, curve in curves.items():
        ax.plot(thresholds, 100.0 * np.asarray(curve), label=label)
    ax.set_xlabel("geodesic error (normalised)")
    ax.set_ylabel("% correspondences")
    ax.set_xlim(thresholds[0], thresholds[-1])
    ax.set_ylim(0, 100)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right")
    ax.set_title(title)
    return _save_figure(fig, path)


def save_precision_recall(path, recall: np.ndarray, precision: np.ndarray, *, title: str) -> Path:
    """PNG of an interpolated precision–recall curve (the mean over a benchmark's queries)."""
    fig = _figure(figsize=(6, 4.5), dpi=100)
    ax = fig.subplots()
    ax.plot(recall, precision, marker="o")
    ax.set_xlabel("recall")
    ax.set_ylabel("precision (interpolated)")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.grid(alpha=0.3)
    ax.set_title(title)
    return _save_figure(fig, path)


def _draw_query(ax, contour_points: np.ndarray, hue: np.ndarray) -> None:
    """The filled query contour with its points coloured by contour position."""
    closed = np.vstack([contour_points, contour_points[:1]])
    ax.fill(closed[:, 0], closed[:, 1], color="0.9")
    ax.scatter(contour_points[:, 0], contour_points[:, 1], c=hue, s=10)
    ax.set_aspect("equal")
    ax.set_axis_off()
    ax.set_title("query contour")


def save_contour_match(path, contour_points: np.ndarray, mesh, path_vertices: np.ndarray,
                       path_contour_index: np.ndarray, *, title: str = "") -> Path:
    """PNG: the query contour and the matched closed curve over two projections of the mesh
    (:func:`save_curve_comparison` without a ground truth).

    Parameters
    ----------
    contour_points : (m, 2) float
    mesh : TriMesh
    path_vertices : (p,) int
        Mesh vertex of every path step.
    path_contour_index : (p,) int
        Contour point of every path step.
    """
    return save_curve_comparison(path, contour_points, mesh, path_vertices, path_contour_index, None, title=title)


def save_energy_trace(path, energy: np.ndarray, tau: np.ndarray | None = None) -> Path:
    """PNG of an energy trace (one value per linear assignment), one colour per diffusion time."""
    fig = _figure(figsize=(6, 4), dpi=100)
    ax = fig.subplots()
    steps = np.arange(1, energy.size + 1)
    if tau is None:
        ax.plot(steps, energy, marker="o")
    else:
        for value in np.unique(tau)[::-1]:
            sel = tau == value
            ax.plot(steps[sel], energy[sel], marker="o", label=f"t/area = {value:.3g}")
        ax.legend(fontsize=7)
    ax.set_xlabel("linear assignment")
    ax.set_ylabel("QAP energy")
    ax.set_yscale("log")
    ax.grid(alpha=0.3)
    return _save_figure(fig, path)


def save_torus_pictures(path, result) -> Path:
    """PNG of a contour-to-contour result: the two contours, the flat torus with the cost and the path,
    and the 3D product torus with the path."""
    from corrlib.geometry.torus import arclength_angles, path_angles, torus_embedding

    matched = result.path
    a, b = matched.contour_points, matched.target_points
    u, v = arclength_angles(a), arclength_angles(b)
    uv = path_angles(matched.layers, matched.vertices, u, v)
    fig = _figure(figsize=(15, 4.5), dpi=100)
    ax = fig.add_subplot(1, 3, 1)
    m = a.shape[0]
    from matplotlib import cm

    hue = cm.hsv(np.arange(m) / m)[:, :3]
    from corrlib.viewing import contours_side_by_side

    shown_a, shown_b, mirrored = contours_side_by_side(a, b, result.map_xy)
    ax.scatter(shown_a[:, 0], shown_a[:, 1], c=hue, s=8)
    ax.scatter(shown_b[result.map_xy, 0], shown_b[result.map_xy, 1], c=hue, s=8)
    ax.set_aspect("equal")
    ax.set_axis_off()
    ax.set_title("A and B" + (" (mirrored)" if mirrored else "") + ", coloured by the position on A")
    ax = fig.add_subplot(1, 3, 2)
    ax.imshow(np.asarray(matched.product_functions["cost"]).T, origin="lower", extent=(0, 1, 0, 1), aspect="auto",
              cmap="viridis")
    ax.plot(uv[:, 0], np.mod(uv[:, 1], 1.0), ".", color="crimson", ms=2)
    ax.set_xlabel("u (contour A)")
    ax.set_ylabel("v (contour B)")
    ax.set_title("flat torus: cost and correspondence")
    ax = fig.add_subplot(1, 3, 3, projection="3d")
    gu, gv = np.meshgrid(np.linspace(0, 1, 60), np.linspace(0, 1, 30), indexing="ij")
    surf = torus_embedding(gu, gv)
    ax.plot_surface(surf[..., 0], surf[..., 1], surf[..., 2], color="0.85", alpha=0.5, linewidth=0)
    pts = torus_embedding(uv[:, 0], uv[:, 1], 1.0, 0.41)
    ax.plot(pts[:, 0], pts[:, 1], pts[:, 2], color="crimson", lw=2)
    ax.set_box_aspect((1, 1, 0.4))
    ax.set_axis_off()
    ax.set_title("product torus A × B")
    return _save_figure(fig, path)


def save_curve_comparison(path, contour_points: np.ndarray, mesh, path_vertices: np.ndarray,
                          path_contour_index: np.ndarray, gt_vertices: np.ndarray | None, *,
                          title: str = "") -> Path:
    """PNG: the query contour, and the matched and ground-truth curves over two projections of the mesh.

    The mesh is drawn as a faint cloud of its vertices, so neither curve is
    hidden behind the surface (a shaded surface would hide the curve's far
    side); the matched curve and the query are coloured by contour position,
    the ground truth (if given) is black and dashed.

    Parameters
    ----------
    contour_points : (m, 2) float
    mesh : TriMesh
    path_vertices, path_contour_index : (p,) int
        Mesh vertex and contour point of every step of the matched path.
    gt_vertices : (m,) int or None
        Ground-truth vertex of every contour point.
    """
    from matplotlib import cm

    m = contour_points.shape[0]
    hue = cm.hsv(np.arange(m) / m)[:, :3]
    from matplotlib.collections import LineCollection

    fig = _figure(figsize=(15, 5), dpi=90)
    axs = fig.subplots(1, 3)
    _draw_query(axs[0], contour_points, hue)
    axes = view_axes(mesh.vertices)
    v = (mesh.vertices - mesh.vertices.mean(axis=0)) @ axes.T
    curve = v[path_vertices]
    for ax, (a, b), label in ((axs[1], (0, 2), "side view"), (axs[2], (0, 1), "top view")):
        ax.scatter(v[:, a], v[:, b], s=0.3, color="0.8")
        if gt_vertices is not None:
            gt = v[np.r_[gt_vertices, gt_vertices[:1]]]
            ax.plot(gt[:, a], gt[:, b], color="black", lw=1.0, ls="--", label="ground truth")
            ax.legend(loc="lower right")
        segments = np.stack([curve[:-1][:, [a, b]], curve[1:][:, [a, b]]], axis=1)
        ax.add_collection(LineCollection(segments, colors=hue[np.asarray(path_contour_index[:-1]) % m], lw=2.5))
        ax.set_title(f"{mesh.name}: {label}")
        ax.set_aspect("equal")
        ax.set_axis_off()
    if title:
        fig.suptitle(title)
    return _save_figure(fig, path)
