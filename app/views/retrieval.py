"""Retrieval view: rank a folder of meshes by 2D-to-3D matching energy; a gallery of the ranking."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from PySide6.QtCore import QSize, Qt, Signal
from PySide6.QtGui import QIcon, QPixmap
from PySide6.QtWidgets import (
    QFileDialog,
    QHBoxLayout,
    QLabel,
    QListWidget,
    QListWidgetItem,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

THUMBNAIL_PX = 160  # gallery thumbnails are square, this many pixels wide
THUMBNAIL_DPI = 80
GALLERY_SPACING_PX = 8
THUMBNAIL_GREY = 0.8  # colour of the mesh in a thumbnail (the matched curve is crimson)
CURVE_LIFT = 0.01  # the matched curve is drawn this fraction of the mesh extent towards the viewer


def thumbnail_png(mesh, path_vertices: np.ndarray | None, size: int = THUMBNAIL_PX) -> bytes:
    """PNG bytes of a mesh with its matched curve (matplotlib figure, safe in a worker thread)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from corrlib.plotting import draw_mesh, view_axes

    fig = Figure(figsize=(size / THUMBNAIL_DPI, size / THUMBNAIL_DPI), dpi=THUMBNAIL_DPI)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1, projection="3d")
    draw_mesh(ax, mesh.vertices, mesh.faces, np.full((mesh.n_vertices, 3), THUMBNAIL_GREY))
    if path_vertices is not None:
        axes = view_axes(mesh.vertices)
        pts = (mesh.vertices[path_vertices] - mesh.vertices.mean(axis=0)) @ axes.T
        ax.plot(pts[:, 0], pts[:, 1] - CURVE_LIFT * np.ptp(pts), pts[:, 2], color="crimson", lw=2)
    fig.subplots_adjust(0, 0, 1, 1)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def retrieval_job(query, folder: str, params=None):
    """Job factory for the worker: ranking plus thumbnails (numpy/bytes only)."""
    from corrlib.io import load_mesh
    from corrlib.retrieval import mesh_files, retrieve

    def factory(token):
        files = mesh_files(folder)
        hits = yield from retrieve(query, files, params, token=token)
        thumbs = []
        for hit in hits:
            token.raise_if_cancelled()
            try:
                thumbs.append(thumbnail_png(load_mesh(hit.path), hit.path_vertices))
            except Exception:  # a broken mesh has no thumbnail; its error is listed
                thumbs.append(b"")
        return hits, thumbs

    return factory


class RetrievalView(QWidget):
    """Query from the sketch canvas or an image, a folder of meshes, a ranked gallery."""

    open_pair = Signal(object, str)  # query Contour2D, mesh path
    run_requested = Signal()

    def __init__(self, parent=None):
        super().__init__(parent)
        self.query = None
        self.folder: str | None = None
        self.query_label = QLabel("query: none (draw a sketch and press Use, or load a silhouette)")
        self.folder_label = QLabel("folder: none")
        choose = QPushButton("Choose folder…")
        choose.clicked.connect(self.choose_folder)
        self.run_button = QPushButton("Rank")
        self.run_button.clicked.connect(self.run_requested)
        self.gallery = QListWidget()
        self.gallery.setViewMode(QListWidget.IconMode)
        self.gallery.setIconSize(QSize(THUMBNAIL_PX, THUMBNAIL_PX))
        self.gallery.setResizeMode(QListWidget.Adjust)
        self.gallery.setSpacing(GALLERY_SPACING_PX)
        self.gallery.itemDoubleClicked.connect(self._open)
        for label in (self.query_label, self.folder_label):
            label.setWordWrap(True)  # long paths and hints wrap instead of widening the window
        top = QHBoxLayout()
        top.addWidget(self.query_label, 1)
        top.addWidget(self.folder_label, 1)
        top.addWidget(choose)
        top.addWidget(self.run_button)
        layout = QVBoxLayout(self)
        layout.addLayout(top)
        layout.addWidget(self.gallery, 1)
        self.hits = []

    def set_query(self, contour) -> None:
        self.query = contour
        self.query_label.setText(f"query: {contour.name} ({contour.n_points} points)")

    def set_folder(self, folder: str) -> None:
        self.folder = folder
        self.folder_label.setText(f"folder: {folder}")

    def choose_folder(self) -> None:
        folder = QFileDialog.getExistingDirectory(self, "Folder of meshes")
        if folder:
            self.set_folder(folder)

    def show_results(self, hits, thumbs) -> None:
        self.hits = hits
        self.gallery.clear()
        for rank, (hit, png) in enumerate(zip(hits, thumbs), 1):
            text = f"{rank}. {hit.path.name}\n" + (f"E = {hit.energy:.4g}" if not hit.error else "failed")
            item = QListWidgetItem(text)
            if png:
                pix = QPixmap()
                pix.loadFromData(png)
                item.setIcon(QIcon(pix))
            item.setToolTip(hit.error or f"{hit.path}\nenergy {hit.energy:.6g}, {hit.seconds:.2f} s")
            item.setData(Qt.UserRole, str(hit.path))
            self.gallery.addItem(item)

    def ranked_names(self) -> list[str]:
        return [Path(self.gallery.item(i).data(Qt.UserRole)).name for i in range(self.gallery.count())]

    def _open(self, item) -> None:
        if self.query is not None:
            self.open_pair.emit(self.query, item.data(Qt.UserRole))

    def close_plotters(self) -> None:
        pass
