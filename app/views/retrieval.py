"""Retrieval view: rank a folder of meshes by 2D-to-3D matching energy; a gallery of the ranking."""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
from PySide6.QtCore import QSize, Qt, QTimer, Signal
from PySide6.QtGui import QIcon, QPixmap
from PySide6.QtWidgets import (
    QComboBox,
    QFileDialog,
    QHBoxLayout,
    QLabel,
    QListWidget,
    QListWidgetItem,
    QPushButton,
    QStyle,
    QVBoxLayout,
    QWidget,
)

THUMBNAIL_PX = 320  # gallery thumbnails are rendered square at this many pixels and shown at most this large
THUMBNAIL_MIN_PX = 120  # a gallery scrolls rather than show its thumbnails smaller than this
GALLERY_SPACING_PX = 8
CAPTION_LINES = 2  # a thumbnail's caption: "rank. name" and the score
CAPTION_ROLE = Qt.UserRole + 1  # a gallery item's caption lines in full (the shown text is elided to its cell)
THUMBNAIL_GREY = 0.8  # colour of the mesh in a thumbnail (the matched curve is crimson)
CURVE_TUBE_RADIUS = 0.012  # radius of the matched curve's tube in display units (unit diagonal)


class ThumbnailRenderer:
    """Gallery thumbnails drawn off screen by VTK with the studio's framing (GUI thread only).

    One off-screen plotter is reused for every thumbnail: the mesh in its
    display frame (:class:`app.views.camera.ShapeDisplay`, the up-axis
    setting of the 3D views) seen as the query shows it, and the matched
    curve as a crimson tube (see :meth:`png`).
    """

    def __init__(self, size: int = THUMBNAIL_PX):
        self.size = size
        self._plotter = None

    def _get(self):
        if self._plotter is None:
            import pyvista as pv

            self._plotter = pv.Plotter(off_screen=True, window_size=(self.size, self.size))
            self._plotter.set_background("white")
        return self._plotter

    def png(self, mesh, path_vertices: np.ndarray | None, up: str = "auto", outline: np.ndarray | None = None) -> bytes:
        """PNG bytes of the thumbnail of ``mesh`` with its matched curve (``path_vertices``, (p,) int).

        ``outline`` ((p, 2) float, the query's point matched to each curve vertex): the mesh is seen from the
        upright view (front, back, either side or top) from which the curve looks most like the outline
        (:func:`corrlib.viewing.outline_frame`); without it, from the front preset.
        """
        from PIL import Image

        from app.views.camera import DISPLAY_FRAME, ShapeDisplay, apply_camera, show_preset
        from app.views.scene import lifted_curve, outward_normals, polydata
        from corrlib.viewing import fitted_camera, outline_frame

        plotter = self._get()
        plotter.clear_actors()
        display = ShapeDisplay.of(mesh.vertices, up)
        points = display.points(mesh.vertices)
        plotter.add_mesh(polydata(points, mesh.faces), color=[THUMBNAIL_GREY] * 3, smooth_shading=True)
        curve = None if path_vertices is None or len(path_vertices) < 2 else points[path_vertices]
        if curve is not None:
            lifted = lifted_curve(points, display.directions(outward_normals(mesh)), path_vertices, CURVE_TUBE_RADIUS)
            plotter.add_mesh(lifted.tube(radius=CURVE_TUBE_RADIUS), color="crimson")
        if curve is not None and outline is not None and len(np.unique(path_vertices)) > 2:
            apply_camera(plotter, fitted_camera(points, outline_frame(curve, outline, DISPLAY_FRAME)))
        else:
            show_preset(plotter, [points], "front")
        plotter.render()  # the screenshot reads the last frame drawn, which add_mesh drew with the last camera
        image = plotter.screenshot(return_img=True)
        buf = io.BytesIO()
        Image.fromarray(image).save(buf, format="PNG")
        return buf.getvalue()

    def close(self) -> None:
        if self._plotter is not None:
            self._plotter.close()
            self._plotter = None


def not_matched_pixmap() -> QPixmap:
    """The gallery's picture for a mesh that could not be matched: a light grey square saying so."""
    from PySide6.QtGui import QColor, QFont, QPainter

    pixmap = QPixmap(THUMBNAIL_PX, THUMBNAIL_PX)
    pixmap.fill(QColor(236, 236, 236))
    painter = QPainter(pixmap)
    font = QFont()
    font.setPixelSize(THUMBNAIL_PX // 10)
    painter.setFont(font)
    painter.setPen(QColor(110, 110, 110))
    painter.drawText(pixmap.rect(), Qt.AlignCenter, "not matched")
    painter.end()
    return pixmap


def gallery_icon_px(width: int, height: int, n_items: int, caption_px: int, spacing: int = GALLERY_SPACING_PX,
                    smallest: int = THUMBNAIL_MIN_PX, largest: int = THUMBNAIL_PX) -> int:
    """Side in pixels of the square thumbnails of a gallery ``width`` × ``height`` pixels holding ``n_items``.

    Every cell is the thumbnail plus ``spacing`` around it and a caption ``caption_px`` high below it. The side
    is the largest (up to ``largest``) at which all items are in sight, over every number of columns. If even
    ``smallest`` does not let them all be seen, the gallery scrolls, and the side is the one at which whole
    columns of at least ``smallest`` fill the width, so that no strip is left empty at the right.
    """
    n_items = max(n_items, 1)
    usable_w, usable_h = width - spacing, height - spacing
    in_sight = max(min(usable_w // cols - spacing, usable_h // math.ceil(n_items / cols) - spacing - caption_px)
                   for cols in range(1, n_items + 1))
    if in_sight >= smallest:
        return min(in_sight, largest)
    cols = max(1, usable_w // (smallest + spacing))
    return int(np.clip(usable_w // cols - spacing, 1, largest))


def matched_outline(hit) -> np.ndarray | None:
    """(p, 2) float: the query's point matched to each vertex of a hit's curve; None for a failed hit."""
    if hit.error or hit.contour_points is None or hit.path_contour_index is None:
        return None
    return np.asarray(hit.contour_points)[np.asarray(hit.path_contour_index)]


def retrieval_job(query, folder: str, params=None, ranking: str = "fused"):
    """Job factory for the worker: the ranking (:func:`corrlib.retrieval.retrieve`'s ``ranking``) and every
    ranked mesh (numpy only; thumbnails are drawn by the view)."""
    from corrlib.errors import CorrError
    from corrlib.io import load_mesh
    from corrlib.retrieval import mesh_files, retrieve

    def factory(token):
        files = mesh_files(folder)
        hits = yield from retrieve(query, files, params, token=token, root=folder, ranking=ranking)
        meshes = []
        for hit in hits:
            token.raise_if_cancelled()
            try:
                meshes.append(None if hit.error else load_mesh(hit.path))
            except CorrError:  # a broken mesh has no thumbnail; its error is listed
                meshes.append(None)
        return hits, meshes

    return factory


class _Gallery(QListWidget):
    """The ranked thumbnails; says when its size changes, so that the thumbnails can be fitted again."""

    resized = Signal()

    def resizeEvent(self, event) -> None:
        super().resizeEvent(event)
        self.resized.emit()


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
        from corrlib.retrieval import RANKINGS

        self.ranking = QComboBox()
        self.ranking.addItems(list(RANKINGS))
        self.ranking.setToolTip("fused: the matching energy times the sketch's dissimilarity to each mesh's rendered "
                                "outlines; energy: the matching energy alone (the thesis' ranking). Either way the "
                                "lowest score ranks first.")
        self.run_button = QPushButton("Rank")
        self.run_button.clicked.connect(self.run_requested)
        self.gallery = _Gallery()
        self.gallery.setViewMode(QListWidget.IconMode)
        self.gallery.setResizeMode(QListWidget.Adjust)
        self.gallery.setMovement(QListWidget.Static)
        self.gallery.setWordWrap(True)
        self.gallery.resized.connect(self.fit_thumbnails)
        self.gallery.itemDoubleClicked.connect(self._open)
        for label in (self.query_label, self.folder_label):
            label.setWordWrap(True)  # long paths and hints wrap instead of widening the window
        top = QHBoxLayout()
        top.addWidget(self.query_label, 1)
        top.addWidget(self.folder_label, 1)
        top.addWidget(choose)
        top.addWidget(QLabel("ranking"))
        top.addWidget(self.ranking)
        top.addWidget(self.run_button)
        layout = QVBoxLayout(self)
        layout.addLayout(top)
        layout.addWidget(self.gallery, 1)
        self.hits = []
        self._pending: list = []  # (item, hit, mesh) whose thumbnails are still to be drawn, best last
        self.thumbnails = ThumbnailRenderer()
        self.up = "auto"  # the up-axis setting of the 3D views (thumbnails follow it)

    def set_query(self, contour) -> None:
        self.query = contour
        from corrlib.retrieval import retrieval_params

        self.query_label.setText(f"query: {contour.name} ({contour.n_points} points, matched at "
                                 f"{retrieval_params().n_contour})")

    def set_folder(self, folder: str) -> None:
        self.folder = folder
        self.folder_label.setText(f"folder: {Path(folder).name or folder}")  # the whole path in the tooltip
        self.folder_label.setToolTip(str(Path(folder).resolve()))

    def choose_folder(self) -> None:
        folder = QFileDialog.getExistingDirectory(self, "Folder of meshes")
        if folder:
            self.set_folder(folder)

    def clear_results(self) -> None:
        """An empty gallery (a new ranking starts: the last folder's must not stand for it if it fails)."""
        self.hits = []
        self._pending = []
        self.gallery.clear()

    def show_results(self, hits, meshes) -> None:
        """The ranked gallery: ``hits`` (best first) and their meshes (None where loading failed).

        The ranks and scores are listed at once; the thumbnails are drawn one per turn of the event loop
        (:meth:`draw_next_thumbnail`), best first, so that a large collection does not freeze the window.
        """
        self.hits = hits
        self.gallery.clear()
        self._pending = []
        for rank, (hit, mesh) in enumerate(zip(hits, meshes), 1):
            figure = "not matched" if hit.error else f"score {hit.score:.4g}" + (" (short curve)"
                                                                                 if hit.collapse_note() else "")
            item = QListWidgetItem(f"{rank}. {hit.name}\n{figure}")
            item.setData(CAPTION_ROLE, (f"{rank}. {hit.name}", figure))
            if mesh is None:  # a picture saying so keeps the caption below the picture's place, as in other cells
                item.setIcon(QIcon(not_matched_pixmap()))
            views = f"{hit.view_distance:.3f}" if np.isfinite(hit.view_distance) else "not measured"
            collapsed = f"\n{hit.collapse_note()}" if hit.collapse_note() else ""
            item.setToolTip(hit.error or f"{hit.path}\nscore {hit.score:.6g}, lower is closer (matching energy "
                                         f"{hit.energy:.6g}, view dissimilarity {views}), {hit.seconds:.2f} s"
                                         f"{collapsed}")
            item.setData(Qt.UserRole, str(hit.path))
            item.setTextAlignment(Qt.AlignHCenter | Qt.AlignTop)
            self.gallery.addItem(item)
            if mesh is not None:
                self._pending.append((item, hit, mesh))
        self.fit_thumbnails()
        self._pending.reverse()  # popped from the end: best first
        QTimer.singleShot(0, self.draw_next_thumbnail)

    def draw_next_thumbnail(self) -> bool:
        """Draw the next pending thumbnail; False when none is left (a new ranking drops the old ones)."""
        if not self._pending:
            return False
        item, hit, mesh = self._pending.pop()
        png = self.thumbnails.png(mesh, hit.path_vertices, self.up, matched_outline(hit))
        pix = QPixmap()
        pix.loadFromData(png)
        item.setIcon(QIcon(pix))
        if self._pending:
            QTimer.singleShot(0, self.draw_next_thumbnail)
        return True

    def thumbnails_pending(self) -> int:
        """How many thumbnails of the ranking shown are still to be drawn."""
        return len(self._pending)

    def fit_thumbnails(self) -> None:
        """Thumbnails as large as the gallery allows for the items it holds (:func:`gallery_icon_px`)."""
        gallery = self.gallery
        viewport = gallery.maximumViewportSize()  # the size without scroll bars
        # a wrapping list lays its items out in the width left beside a vertical scroll bar, shown or not
        width = viewport.width() - gallery.style().pixelMetric(QStyle.PM_ScrollBarExtent, None, gallery)
        caption_px = CAPTION_LINES * gallery.fontMetrics().lineSpacing() + 4
        side = gallery_icon_px(width, viewport.height(), gallery.count(), caption_px)
        gallery.setIconSize(QSize(side, side))
        # where the height limits the side, the columns are spread over the width (each thumbnail centred in a
        # wider cell) instead of leaving a strip empty at the right
        usable = width - GALLERY_SPACING_PX
        cols = max(1, min(gallery.count(), usable // (side + GALLERY_SPACING_PX)))
        gallery.setGridSize(QSize(max(side + GALLERY_SPACING_PX, usable // cols),
                                  side + caption_px + GALLERY_SPACING_PX))
        metrics = gallery.fontMetrics()
        for i in range(gallery.count()):  # a long name shortened in its middle, so that the score stays in sight
            item = gallery.item(i)
            lines = item.data(CAPTION_ROLE) or (item.text(),)
            item.setText("\n".join(metrics.elidedText(line, Qt.ElideMiddle, side) for line in lines))

    def ranked_names(self) -> list[str]:
        return [Path(self.gallery.item(i).data(Qt.UserRole)).name for i in range(self.gallery.count())]

    def _open(self, item) -> None:
        if self.query is not None:
            self.open_pair.emit(self.query, item.data(Qt.UserRole))

    def close_plotters(self) -> None:
        self._pending = []
        self.thumbnails.close()
