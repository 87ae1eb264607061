"""How much a mesh, seen from some direction, looks like a drawn outline: the inner-distance shape context
of the drawing against the mesh's rendered outlines (a second opinion for retrieval, :mod:`corrlib.retrieval`).

``contour3d``'s energy compares the features of the filled drawing with those of the surface, which holds
across poses but asks a drawing to have the proportions of the surface's curves. View-based sketch retrieval
compares like with like instead: the mesh is rendered orthographically from the 13 directions of its
principal box (:func:`~corrlib.methods.contour_views.view_directions`), and the drawing is compared with every
outline, 2D to 2D. The comparison is the inner-distance shape context (:mod:`corrlib.descriptors.shape_context`,
Ling & Jacobs 2007), built for outlines of articulated shapes, and aligned along the outlines in order; the
drawing's mirror image is compared too (a drawing has no front or back; the opposite viewing direction is the
mirror image of a view). The dissimilarity is the lowest over the views and both readings.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from corrlib.descriptors.shape_context import (N_ANGLE_BINS, N_DISTANCE_BINS, OUTLINE_POINTS, outline_context,
                                               outline_dissimilarity)
from corrlib.errors import ContourError
from corrlib.geometry.sections import principal_frame
from corrlib.methods.contour_views import outline_along, reading_contexts, view_directions
from corrlib.shapes import Contour2D

#: pixels along the longer side of every rendered view (as ``contour-views``)
VIEW_RESOLUTION = 256


@dataclass(frozen=True)
class QueryOutline:
    """A drawing ready for :func:`view_dissimilarity`.

    Attributes
    ----------
    contexts : tuple of two (n, d) float
        :func:`~corrlib.descriptors.shape_context.inner_shape_context` of the drawing as drawn and of its mirror
        image, both resampled to :data:`OUTLINE_POINTS` points, counter-clockwise.
    """

    contexts: tuple


def query_outline(contour: Contour2D) -> QueryOutline:
    """The drawing's shape contexts, as drawn and mirrored (:func:`~corrlib.methods.contour_views.mirror_image`;
    a reflection turns the outline clockwise, which :meth:`~corrlib.shapes.Contour2D.ccw` turns back)."""
    return QueryOutline(reading_contexts(contour))


def view_contexts(mesh, use_cache: bool = True) -> np.ndarray:
    """Shape contexts of the mesh's outlines along the 13 directions of its principal box, cached on disk by
    mesh content (:mod:`corrlib.cache`: a collection is rendered once, not once per query); a direction whose
    projection has no usable outline (too thin to trace at :data:`VIEW_RESOLUTION`) is left out.

    Returns
    -------
    (v, OUTLINE_POINTS, d) float
        ``v ≤ 13`` views (``v = 0`` where none has an outline).
    """
    from corrlib import cache

    key = cache.make_key("view-shape-context-v1", mesh.content_hash, OUTLINE_POINTS, VIEW_RESOLUTION)
    schema = {"contexts": cache.Array("f", (None, OUTLINE_POINTS, N_DISTANCE_BINS * N_ANGLE_BINS))}
    entry = cache.load("view-contexts", key, schema) if use_cache else None
    if entry is not None:
        return entry["contexts"]
    _, axes = principal_frame(mesh)
    contexts = []
    for direction in view_directions(axes, "box"):
        try:
            outline, _ = outline_along(mesh, direction, VIEW_RESOLUTION)
            contexts.append(outline_context(outline))
        except ContourError:
            continue
    contexts = np.array(contexts).reshape(len(contexts), OUTLINE_POINTS, N_DISTANCE_BINS * N_ANGLE_BINS)
    if use_cache:
        cache.store("view-contexts", key, {"contexts": contexts})
    return contexts


def view_dissimilarity(query: QueryOutline, mesh) -> float:
    """The lowest :func:`~corrlib.descriptors.shape_context.outline_dissimilarity` of the drawing (either
    reading) to any of the mesh's views; NaN where no view has an outline.

    Parameters
    ----------
    query : QueryOutline
    mesh : TriMesh
    """
    views = view_contexts(mesh)
    if len(views) == 0:
        return float("nan")
    return min(outline_dissimilarity(reading, view) for reading in query.contexts for view in views)
