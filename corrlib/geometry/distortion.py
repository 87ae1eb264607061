"""How far a vertex map is from an isometry, measured by geodesic distances.

A map ``m: X → Y`` is an isometry when it keeps every geodesic distance,
``d_Y(m(a), m(b)) = d_X(a, b)``. Its *geodesic distortion* is the mean
deviation over pairs of well spread samples ``a, b`` of ``X``,

    D(m) = mean over a, b of | d_X(a, b) / √A_X − d_Y(m(a), m(b)) / √A_Y |,

each shape's distances in units of the square root of its area (a match is
sought up to scale). No ground truth enters, so it can judge maps that an
intrinsic energy cannot tell apart: the heat kernels and spectral descriptors
are smooth and global, while a path between two limbs runs through the body,
so a map that swaps or twists limbs changes such paths by the body's width.
The distances are shortest edge paths (Dijkstra on the edge graph), which
overestimate the true geodesics by a few per cent alike on both shapes; the
distortion compares maps of one pair, so the bias cancels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: farthest-point samples of the source between which the distances are compared (100 Dijkstra runs per map)
GEODESIC_SAMPLES = 100


class PairDistances:
    """The edge-path distances that the distortion of maps of one pair compares, each computed once.

    The source's :data:`GEODESIC_SAMPLES` outermost farthest points (:attr:`sample`), their distances to every
    source vertex (:attr:`from_sample`), and for each set of images on the target their distances to every
    target vertex (:meth:`from_images`) and between them (:meth:`between_images`). All per square root of the
    shape's area.
    """

    def __init__(self, source, target):
        from corrlib.geometry.geodesics import GeodesicSolver
        from corrlib.geometry.sampling import outermost_farthest_points

        self.source, self.target = source, target
        self.sample = outermost_farthest_points(source.vertices, min(GEODESIC_SAMPLES, source.n_vertices))
        self._solver_x = GeodesicSolver(source)
        self._solver_y = self._solver_x if target is source else GeodesicSolver(target)
        self._from_sample = None
        self._rows = {}  # target vertex -> its distances to every target vertex
        self._parts = {}  # map bytes -> inconsistent_parts of that map

    @property
    def from_sample(self) -> np.ndarray:
        """(s, n_X) float: distances from the samples to every source vertex."""
        if self._from_sample is None:
            self._from_sample = self._solver_x.distances(self.sample, method="graph") / np.sqrt(self.source.area)
        return self._from_sample

    def from_images(self, images: np.ndarray) -> np.ndarray:
        """(k, n_Y) float: distances from the target vertices ``images`` (k,) int to every target vertex. Each
        vertex's row is computed once: the judges of one match ask about the same maps, and about maps made of
        their parts."""
        images = np.asarray(images)
        missing = np.array(sorted(set(images.tolist()) - self._rows.keys()), dtype=np.int64)
        if missing.size:
            rows = self._solver_y.distances(missing, method="graph") / np.sqrt(self.target.area)
            self._rows.update(zip(missing.tolist(), rows))
        return np.array([self._rows[vertex] for vertex in images.tolist()]).reshape(images.size, -1)

    def between_images(self, images: np.ndarray) -> np.ndarray:
        """(k, k) float: distances between the target vertices ``images`` (k,) int."""
        return self.from_images(images)[:, images]

    def sample_distortions(self, map_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The samples a map matches, (k,) int positions in :attr:`sample`, and each one's mean distortion
        against the others, (k,) float (the rows of :meth:`pair_distortions`, whose mean is :math:`D(m)`)."""
        matched, pair_distortion = self.pair_distortions(map_xy)
        return matched, pair_distortion.mean(axis=1) if matched.size >= 2 else np.zeros(matched.size)

    def pair_distortions(self, map_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The samples a map matches, (k,) int positions in :attr:`sample`, and the distortion of every pair of
        them, (k, k) float ``|d_X(a, b)/√A_X − d_Y(m a, m b)/√A_Y|``."""
        images = np.asarray(map_xy)[self.sample]
        matched = np.flatnonzero(images >= 0)
        if matched.size < 2:  # no pair
            return matched, np.zeros((matched.size, matched.size))
        before = self.from_sample[np.ix_(matched, self.sample[matched])]
        return matched, np.abs(before - self.between_images(images[matched]))


def geodesic_distortions(source, target, maps, distances: PairDistances | None = None) -> list[float]:
    """:math:`D(m)` (module docstring) of several maps of one pair, the source's distances computed once.

    Parameters
    ----------
    source, target : TriMesh
    maps : sequence of (n_X,) int
        Target vertex of every source vertex; -1 (unmatched) leaves the sample out of that map's mean.
    distances : PairDistances, optional
        The pair's distances, shared with other judges of the same maps.

    Returns
    -------
    list of float
        One distortion per map, in their order; ``nan`` for a map that matches fewer than two samples.
    """
    distances = PairDistances(source, target) if distances is None else distances
    out = []
    for map_xy in maps:
        matched, pair_distortion = distances.pair_distortions(map_xy)
        out.append(float(np.mean(pair_distortion)) if matched.size >= 2 else float("nan"))
    return out


#: a map is read as two parts that disagree when the mean distortion between them is more than this many times
#: the mean within them (right maps stay below, maps with a part turned against the rest above: the figures are
#: in ``docs/decisions.md``, 2026-12-05) ...
DISAGREEMENT_RATIO = 3.0
#: ... and more than this many mean edge lengths: each of the two edge-path distances compared can be about an
#: edge off the geodesic, so a smaller disagreement is below what the measurement resolves (a nearly exact map,
#: whose ratio is large only because the distortion within the parts is nearly zero)
RESOLVED_EDGES = 2.0


@dataclass(frozen=True)
class MapParts:
    """A map's two mutually most inconsistent parts (:func:`inconsistent_parts`).

    Attributes
    ----------
    part : (n_X,) bool
        Source vertices of the first part (each vertex takes the part of its geodesically nearest sample); the
        rest form the second.
    ratio : float
        Mean pair distortion between the parts over the mean within them (1 for a split that tells nothing).
    between : float
        Mean pair distortion between the parts, per √area.
    resolution : float
        The larger of the two shapes' mean edge lengths, per √area (:attr:`TriMesh.relative_edge_length`).
    """

    part: np.ndarray
    ratio: float
    between: float
    resolution: float

    @property
    def disagree(self) -> bool:
        """Whether the parts are two near-isometries that disagree with each other: by more than
        :data:`DISAGREEMENT_RATIO` times the distortion within them and by more than :data:`RESOLVED_EDGES` edges."""
        return self.ratio > DISAGREEMENT_RATIO and self.between > RESOLVED_EDGES * self.resolution


def inconsistent_parts(source, target, map_xy: np.ndarray,
                       distances: PairDistances | None = None) -> MapParts | None:
    """Split a map into the two parts whose geodesic distances disagree most with each other.

    With farthest-point samples ``a, b`` of the source, the pair distortion is
    ``E_ab = | d_X(a, b)/√A_X − d_Y(m a, m b)/√A_Y |`` (the terms of :math:`D(m)`, module docstring). A map
    that is right on one part of the shape and turned on another (an upper body mapped half a turn round
    against the hips) is two near-isometries: ``E`` is small within each part and of the order of the body's
    width between them, while a right map's ``E`` has no such structure. The parts are the normalised-cut
    bipartition (Shi & Malik 2000) of the affinity ``W_ab = exp(−(E_ab / median E)²)``: the signs of the
    second eigenvector ``v`` of ``D^{-1/2} W D^{-1/2}`` scaled by ``D^{-1/2}``, with ``D`` the row sums.

    Parameters
    ----------
    source, target : TriMesh
        Connected shapes.
    map_xy : (n_X,) int
        Target vertex of every source vertex; -1 (unmatched) leaves a sample out.
    distances : PairDistances, optional
        The pair's distances, shared with other judges of the same map.

    Returns
    -------
    MapParts or None
        None where fewer than four samples are matched or a distance is infinite (a disconnected shape).
    """
    distances = PairDistances(source, target) if distances is None else distances
    key = np.asarray(map_xy).tobytes()
    if key not in distances._parts:  # the judges of one match split the same map
        distances._parts[key] = _split(source, target, map_xy, distances)
    return distances._parts[key]


def _split(source, target, map_xy: np.ndarray, distances: PairDistances) -> MapParts | None:
    """:func:`inconsistent_parts`, computed."""
    matched, pair_distortion = distances.pair_distortions(map_xy)
    if matched.size < 4 or not (np.all(np.isfinite(pair_distortion)) and np.all(np.isfinite(distances.from_sample))):
        return None
    scale = np.median(pair_distortion)
    resolution = max(source.relative_edge_length, target.relative_edge_length)
    nothing = MapParts(np.ones(source.n_vertices, dtype=bool), 1.0, 0.0, resolution)
    if not scale > 0:  # an isometry on more than half the pairs: nothing to split
        return nothing
    affinity = np.exp(-(pair_distortion / scale) ** 2)
    degree = affinity.sum(axis=1)
    _, vectors = np.linalg.eigh(affinity / np.sqrt(np.outer(degree, degree)))
    side = vectors[:, -2] / np.sqrt(degree) > 0  # eigh orders ascending: the last is the trivial √D
    if side.all() or not side.any():
        return nothing
    between = pair_distortion[np.ix_(side, ~side)].mean()
    within = (pair_distortion[np.ix_(side, side)].sum() + pair_distortion[np.ix_(~side, ~side)].sum()) / \
        (side.sum() ** 2 + (~side).sum() ** 2)
    ratio = float(between / within) if within > 0 else float("inf")
    owner = np.argmin(distances.from_sample[matched], axis=0)  # each vertex's geodesically nearest sample
    return MapParts(side[owner], ratio, float(between), resolution)
