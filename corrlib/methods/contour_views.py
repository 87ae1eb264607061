"""2D-to-3D matching through the mesh's own outlines (``contour-views``): a drawing read as a view.

:mod:`.contour3d` (thesis ch. 7) matches an outline to any closed curve of the surface by comparing the
features of the filled outline with those of the surface. That is what makes it pose-invariant, and what
makes it fragile on a *drawing*: a drawing is the outline of a projection, the features of a flat filled
outline are not those of a curved surface, and a drawing's proportions are not the mesh's, so several
curves of the surface come within a few per cent of each other's energy (``docs/decisions.md``).

This method compares like with like, as view-based sketch retrieval does. The mesh is rendered
orthographically from the 13 directions of its principal box (:func:`view_directions`; the opposite
direction gives the mirror image, which the mirrored reading below covers). Every outline is matched to the
query on their product torus with the 2D-to-2D energy of :mod:`.contour2d` (both filled outlines at unit
area), per unit length of the torus' diagonal so that views with longer outlines are not handicapped
(:func:`diagonal_length`), for the query as drawn and for its mirror image (a drawing has no front or back).

Which view: the torus energy compares features of the filled outlines (WKS), which tell *where* two outlines
correspond but are a weak judge of *which* outline the drawing shows: a compact view (the body seen end-on)
has bland features that half-match anything, and a drawing's stick legs are not the mesh's. Every torus'
costs are therefore multiplied by how unlike its reading of the drawing the view's outline is by
inner-distance shape context (:func:`view_unlikeness`; Ling & Jacobs 2007, built to compare outlines of
articulated shapes), the product retrieval ranks by (:mod:`corrlib.retrieval`). A constant factor per torus
leaves each torus' optimal path as it is and decides between the views and readings (``view_choice="energy"``:
the energy alone).

**One branch-and-bound over all these graphs** gives the global optimum over every view and both readings (or a
``1 + eps`` approximation). Each matched point of the winning view's outline is taken to the vertex nearest
the viewer among those that project onto it (:func:`~corrlib.geometry.sections.rim_vertices`), and
consecutive vertices are joined by shortest edge paths into a closed curve on the mesh.

What it assumes: the drawing shows the mesh **in the mesh's pose**, seen from about one of the 13
directions. Views are extrinsic: a mesh in another pose has other outlines (a person with raised arms),
which the intrinsic energy of ``contour3d`` does not mind, and a plane section is no view at all. Use
``contour3d`` for those; the two methods answer different questions, and the studio shows both.

Map convention: ``map_xy[i]`` is the mesh vertex of point ``i`` of ``result.path.contour_points`` (the query
resampled to ``n_contour`` points, in its own coordinates, in the order of the winning reading).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from corrlib.descriptors.shape_context import outline_context, outline_dissimilarity
from corrlib.errors import ContourError, InputError
from corrlib.geometry.cyclic_paths import branch_and_bound_union
from corrlib.geometry.geodesics import edge_paths
from corrlib.geometry.sections import SilhouetteProjection, principal_frame, rendered_view, rim_vertices
from corrlib.methods.base import ContourPath, MatchResult, SearchCertificate, param
from corrlib.methods.contour2d import prepared_outline, torus_graph, torus_maps
from corrlib.methods.contour3d import PreparedQuery, node_costs
from corrlib.methods.registry import MethodSpec, register
from corrlib.progress import Progress, Stopwatch
from corrlib.shapes import Contour2D, TriMesh

#: the direction sets of :func:`view_directions`
DIRECTION_SETS = ("box", "axes")
#: how the view is chosen (``view_choice``): by the fused score or by the 2D-to-2D energy alone
VIEW_CHOICES = ("fused", "energy")


@dataclass(frozen=True, kw_only=True)
class ContourViewsParams:
    n_contour: int = param(100, label="Contour points", low=10, high=2000,
                           help="The query is resampled by arc length to this many points.")
    n_view: int = param(100, label="View points", low=10, high=2000,
                        help="Every rendered outline of the mesh is resampled to this many points.")
    directions: str = param("box", label="Views", choices=DIRECTION_SETS,
                            help="box: the 13 directions of the mesh's principal box (its 3 axes, the 6 diagonals "
                                 "of its faces, the 4 diagonals of the box); axes: its 3 principal axes only.")
    resolution: int = param(256, label="View resolution", low=32, high=2048,
                            help="Pixels along the longer side of every rendered view.")
    k: int = param(25, label="Eigenpairs", low=5, high=500, help="Eigenpairs of the filled outlines.")
    n_scales: int = param(100, label="Scales", low=2, high=500, help="Times of the HKS, energies of the WKS.")
    eps: float = param(0.0, label="Approximation ε", low=0.0, high=0.9,
                       help="0: global optimum over every view and both readings; ε > 0: within a factor 1 + ε.")
    max_iterations: int = param(100_000, label="Max iterations", low=1, high=10_000_000,
                                help="Cap on branch-and-bound iterations (the bounds are reported).")
    view_choice: str = param("fused", label="View choice", choices=VIEW_CHOICES,
                             help="fused: the 2D-to-2D energy of every view and reading times how unlike the "
                                  "drawing its outline is by inner-distance shape context (as retrieval fuses "
                                  "them); energy: the 2D-to-2D energy alone.")


@dataclass
class MeshView:
    """One rendered view of a mesh, ready for matching.

    Attributes
    ----------
    direction : (3,) float
        Viewing direction in the mesh's coordinates (unit).
    outline : PreparedQuery
        The outline, resampled to ``n_view`` points (pixel units), with the features of its filled interior.
    projection : SilhouetteProjection
        Where the mesh's vertices land in the same pixel units.
    """

    direction: np.ndarray
    outline: PreparedQuery
    projection: SilhouetteProjection


def view_directions(axes: np.ndarray, which: str = "box") -> np.ndarray:
    """Viewing directions in a principal frame: every ``Σ_k s_k a_k`` with ``s ∈ {−1, 0, 1}³ \\ 0`` up to sign
    (13 for ``"box"``), or the three axes (``"axes"``).

    Parameters
    ----------
    axes : (3, 3) float
        Principal axes as rows.
    which : str
        One of :data:`DIRECTION_SETS`.

    Returns
    -------
    (d, 3) float
        Unit directions, the principal axes first.
    """
    signs = [np.array(s, dtype=np.float64) for s in itertools.product((1, 0, -1), repeat=3)]
    # one of each ± pair: the first non-zero sign positive; the axes first, in their order
    signs = [s for s in signs if s.any() and s[np.flatnonzero(s)[0]] > 0]
    if which == "axes":
        signs = [s for s in signs if np.count_nonzero(s) == 1]
    signs.sort(key=np.count_nonzero)
    directions = np.array(signs) @ np.asarray(axes, dtype=np.float64)
    return directions / np.linalg.norm(directions, axis=1, keepdims=True)


def outline_along(mesh: TriMesh, direction: np.ndarray, resolution: int) -> tuple[Contour2D, SilhouetteProjection]:
    """:func:`~corrlib.geometry.sections.rendered_view` with any axis across the view as its up direction
    (whatever reads the outline does not depend on its rotation in the image)."""
    helper = np.eye(3)[int(np.argmin(np.abs(direction)))]
    return rendered_view(mesh, direction, resolution, up=np.cross(direction, helper))


def render_view(mesh: TriMesh, direction: np.ndarray, params: ContourViewsParams) -> MeshView | None:
    """The view of ``mesh`` along ``direction``, or None where its outline cannot be matched (a projection
    too thin to fill with enough vertices for ``k`` eigenpairs)."""
    try:
        outline, projection = outline_along(mesh, direction, params.resolution)
        prepared = prepared_outline(Contour2D(outline.points, name=f"{mesh.name} view", validate=False),
                                    params.n_view, params.k, params.n_scales, finer="raise resolution or n_view")
    except ContourError:
        return None
    return MeshView(direction, prepared, projection)


def diagonal_length(points_a: np.ndarray, points_b: np.ndarray) -> float:
    """``sqrt(L_a² + L_b²)``: the length of the shortest closed path around the product torus of two closed
    polygons of lengths ``L_a`` and ``L_b`` (one at uniform speed along both, Euclidean product metric).

    A path's energy integrates the node cost along its length, so a view with a longer outline (legs and
    ears seen from the side) pays for more length than a compact one (the shape seen end-on) at the same
    feature agreement. Dividing each view's costs by this length compares the views by their cost per unit
    length; within a view it is a constant factor and leaves the optimal path unchanged.

    Parameters
    ----------
    points_a : (m, 2) float
    points_b : (n, 2) float
    """
    return float(np.hypot(Contour2D(points_a, validate=False).length, Contour2D(points_b, validate=False).length))


def reading_contexts(drawing: Contour2D) -> tuple[np.ndarray, np.ndarray]:
    """The drawing's inner-distance shape contexts (:func:`~corrlib.descriptors.shape_context.outline_context`)
    as drawn and mirrored (:func:`mirror_image`; the context is taken counter-clockwise, so the reflection's
    reversal of the outline's direction is turned back)."""
    return outline_context(drawing), outline_context(mirror_image(drawing))


def view_unlikeness(drawing: Contour2D, outlines: list[tuple[Contour2D, bool]]) -> np.ndarray:
    """(p,) float: for every view outline and reading of the drawing (as drawn, or ``mirrored``), the
    inner-distance shape context dissimilarity of the reading to the outline (lower: more alike; Ling & Jacobs
    2007), the view dissimilarity retrieval fuses with the energy (:mod:`corrlib.outline_views`)."""
    readings = reading_contexts(drawing)
    contexts = {id(outline): outline_context(outline) for outline, _ in outlines}  # once per view
    return np.array([outline_dissimilarity(readings[int(mirrored)], contexts[id(outline)])
                     for outline, mirrored in outlines])


def mirror_image(contour: Contour2D) -> Contour2D:
    """The contour reflected across its y axis (the same drawing seen from behind the paper)."""
    return Contour2D(contour.points * np.array([-1.0, 1.0]), name=contour.name, validate=False)


def closed_curve(mesh: TriMesh, vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Consecutive matched vertices joined by shortest edge paths into a closed curve.

    Parameters
    ----------
    mesh : TriMesh
        Connected (as :class:`~corrlib.shapes.TriMesh` checks).
    vertices : (m,) int
        Matched vertex of every contour point.

    Returns
    -------
    curve : (k,) int
        The curve's vertices, closed (first = last).
    contour_index : (k,) int
        Contour point of every curve vertex (the point whose step it lies on).
    """
    curve, index = [], []
    for i, path in enumerate(edge_paths(mesh, vertices, np.roll(vertices, -1))):
        curve.extend(path[:-1].tolist() if len(path) > 1 else path.tolist())
        index.extend([i] * max(len(path) - 1, 1))
    curve.append(int(vertices[0]))
    index.append(0)
    return np.array(curve, dtype=np.int64), np.array(index, dtype=np.int64)


def solve_contour_views(source: Contour2D, target: TriMesh, params: ContourViewsParams, token):
    """Registered solver: match a closed contour (source) to a mesh (target) through its rendered views."""
    watch = Stopwatch()
    yield Progress("query features", 0.0)
    with watch("features"):
        readings = [prepared_outline(contour, params.n_contour, params.k, params.n_scales, finer="raise n_contour")
                    for contour in (source, mirror_image(source))]
    _, axes = principal_frame(target)
    directions = view_directions(axes, params.directions)
    views = []
    for number, direction in enumerate(directions):
        token.raise_if_cancelled()
        yield Progress("views", 0.05 + 0.65 * number / len(directions), f"view {number + 1} of {len(directions)}")
        with watch("views"):
            view = render_view(target, direction, params)
        if view is not None:
            views.append(view)
    if not views:
        raise InputError(f"{target.name}: no view of the mesh has an outline that can be matched (every projection "
                         f"is too thin to fill for k={params.k} eigenpairs); raise resolution or lower k")
    pairs = [(view, mirrored) for view in views for mirrored in (False, True)]
    fused = params.view_choice == "fused"
    with watch("features"):
        factors = (view_unlikeness(source, [(view.outline.contour, mirrored) for view, mirrored in pairs])
                   if fused else np.ones(len(pairs)))
        graphs = [torus_graph(factor * node_costs(readings[mirrored].features, view.outline.features)
                              / diagonal_length(readings[mirrored].points, view.outline.points),
                              readings[mirrored].points, view.outline.points)
                  for (view, mirrored), factor in zip(pairs, factors)]
    yield Progress("branch and bound", 0.7, f"{len(graphs)} tori ({len(views)} views, both readings of the query)")
    with watch("search"):
        bb = yield from branch_and_bound_union(graphs, eps=params.eps, token=token,
                                               max_iterations=params.max_iterations)
    view, mirrored = pairs[bb.graph_index]
    query = readings[mirrored]
    _, map_to_outline, _ = torus_maps(bb.path, len(query.points), len(view.outline.points))
    with watch("curve"):
        matched = rim_vertices(view.outline.contour.points[map_to_outline], view.projection)[:, 0]
        curve, contour_index = closed_curve(target, matched)
    points = mirror_image(query.contour).points if mirrored else query.contour.points
    path = ContourPath(points, curve, contour_index, np.append(contour_index[:-1], len(points)))
    direction = ", ".join(f"{x:.3f}" for x in view.direction)
    yield Progress("done", 1.0, f"energy {bb.energy:.6g}, view ({direction}){', mirrored' if mirrored else ''}")
    return MatchResult("contour-views", map_xy=matched, map_yx=None, energy=bb.energy, timings=watch.times,
                       path=path, search=SearchCertificate.of(bb, params.eps),
                       extras={"view_direction": [float(x) for x in view.direction], "mirrored": bool(mirrored),
                               "views": len(views), "views_skipped": len(directions) - len(views),
                               "view_unlikeness": float(factors[bb.graph_index]) if fused else None},
                       energy_meaning=f"2D-to-2D path energy on the product torus of the query and the mesh's "
                                      f"outline seen along ({direction}), per unit length of the torus' diagonal "
                                      "(unit areas)" + (", times the outline's shape-context dissimilarity to the "
                                                        "query" if fused else ""))


register(MethodSpec(
    name="contour-views", label="2D-to-3D through rendered views", inputs=("contour", "mesh"),
    params=ContourViewsParams, solve=solve_contour_views, rank=5,
    description="A drawing read as a view: the mesh's outlines from 13 directions matched to the query on "
                "their product tori (the 2D-to-2D energy times the outline's shape-context dissimilarity), "
                "globally optimal over every view and both readings, then taken to the rim vertices. For drawings "
                "of a mesh in its pose; contour3d for other poses and sections."))
