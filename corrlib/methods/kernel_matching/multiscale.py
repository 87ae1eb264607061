"""Stage 6 (thesis §8.3.2): the finer vertex samples, each scale solved in geodesic Voronoi cells at the
smallest time with every current match as an anchor (:func:`multiscale_refinement`).
"""

from __future__ import annotations

from scipy.sparse.csgraph import dijkstra
import numpy as np

from corrlib.assignment import area_capacities, linear_assignment
from corrlib.cores import side_threads
from corrlib.geometry.sampling import farthest_point_sampling, voronoi_bands, voronoi_cells
from corrlib.methods.kernel_matching.params import PROGRESS_MULTISCALE
from corrlib.methods.kernel_matching.scores import alignment, kernel_score
from corrlib.methods.kernel_matching.state import KernelState, sample_masses
from corrlib.methods.resolution import nearest_partners, surplus_partners
from corrlib.progress import Progress


#: threads solving the cells of a refinement pass: the auction releases the GIL, so cells can overlap; two,
#: for the two-core development machine (every cell in flight also holds its dense score block)
CELL_THREADS = 2
#: cells per pass: enough that an average cell holds this fraction of ``max_cell`` (headroom: geodesic Voronoi
#: cells are uneven)
CELL_FILL = 0.7
#: pass ``p`` starts its farthest-point cell centres at the ``p × CENTRE_STRIDE``-th matched vertex farthest
#: from the centroid, so that every pass draws its cells around different centres (no border stays fixed)
CENTRE_STRIDE = 7


def _best_row_per_column(rows: np.ndarray, cols: np.ndarray, values: np.ndarray, n_cols: int) -> np.ndarray:
    """(n_cols,) int: for every column the row with the highest value among the given (row, col) pairs, -1 if none."""
    out = -np.ones(n_cols, dtype=np.int64)
    if rows.size:
        order = np.lexsort((-values, cols))
        first = np.concatenate([[True], cols[order][1:] != cols[order][:-1]])
        out[cols[order][first]] = rows[order][first]
    return out


def _solve_cells(x_cells, y_cells, psi, phi, c, decay_y, decay_x, params, cancel, n_y, capacity_y=None):
    """One refinement pass: every cell is a (partial) assignment.

    Parameters
    ----------
    x_cells : list of (a_c,) int
        Source samples of every cell (a partition of the sample).
    y_cells : list of (b_c,) int
        Target samples of every cell (they may overlap: widened cells).
    capacity_y : (n_y,) int, optional
        How many source samples each target vertex may take (None: one).

    Returns
    -------
    map_x : (n_x_sample,) int, aligned with ``np.concatenate(x_cells)``
        Target of every source sample (-1: unmatched).
    map_yx : (n_y,) int
        For target vertices in some cell: the best-scoring source sample assigned to it, or (without
        partial matching) the best-scoring source sample of its cells; -1 elsewhere.
    """
    def cell(cid):
        xs, ys = x_cells[cid], y_cells[cid]
        if xs.size == 0 or ys.size == 0:
            return None
        g = kernel_score(phi[xs], psi[ys], c.T, decay_x, decay_y)  # (xs, ys)
        slack = None
        if params.partial:
            slack = float(np.quantile(g.max(axis=1), params.slack_quantile))
        cap = None if capacity_y is None else capacity_y[ys]
        return g, linear_assignment(g, slack=slack, method=params.backend, cancel=cancel, capacity=cap)

    map_x = []
    # reverse map, merged over overlapping cells: an assigned source beats an unassigned one, then the score
    rank_y = np.full((n_y, 2), -np.inf)
    map_yx = -np.ones(n_y, dtype=np.int64)
    with side_threads(CELL_THREADS) as pool:
        for cid, out in enumerate(pool.map(cell, range(len(x_cells)))):
            xs, ys = x_cells[cid], y_cells[cid]
            if out is None:
                map_x.append(-np.ones(xs.size, dtype=np.int64))
                continue
            g, cols = out
            mx = np.where(cols >= 0, ys[np.clip(cols, 0, None)], -1)
            if not params.partial:
                mx = np.where(mx >= 0, mx, ys[np.argmax(g, axis=1)])  # smaller target cell: best score
            map_x.append(mx)
            matched = np.flatnonzero(cols >= 0)
            best_in = _best_row_per_column(matched, cols[matched], g[matched, cols[matched]], ys.size)
            assigned = best_in >= 0
            cand = np.where(assigned, best_in, np.argmax(g, axis=0))
            key = np.column_stack([assigned.astype(float), g[cand, np.arange(ys.size)]])
            if params.partial:
                key[~assigned] = -np.inf
            better = (key[:, 0] > rank_y[ys, 0]) | ((key[:, 0] == rank_y[ys, 0]) & (key[:, 1] > rank_y[ys, 1]))
            rank_y[ys[better]] = key[better]
            map_yx[ys[better]] = xs[cand[better]]
    return np.concatenate(map_x), map_yx


def cell_centres(vertices: np.ndarray, matched_x: np.ndarray, matched_y: np.ndarray, n_cells: int,
                 pass_index: int) -> tuple[np.ndarray, np.ndarray]:
    """Centres of the cells of one pass: farthest points among the matched source vertices.

    The farthest-point set starts at the ``pass_index × CENTRE_STRIDE``-th matched vertex farthest from their
    centroid, so every pass draws different centres; centres are made distinct on both sides (seeds
    snapped to their vertices may share one).

    Returns
    -------
    centres_x, centres_y : (c,) int
        Source vertices and their matched target vertices, ``c ≤ n_cells``.
    """
    matched_pts = vertices[matched_x]
    radius = np.linalg.norm(matched_pts - matched_pts.mean(axis=0), axis=1)
    start = int(np.argsort(-radius, kind="stable")[min(pass_index * CENTRE_STRIDE, radius.size - 1)])
    centres_pos = farthest_point_sampling(matched_pts, min(n_cells, matched_x.size), start=start)
    _, first_x = np.unique(matched_x[centres_pos], return_index=True)
    centres_pos = centres_pos[np.sort(first_x)]
    _, first_y = np.unique(matched_y[centres_pos], return_index=True)
    centres_pos = centres_pos[np.sort(first_y)]
    return matched_x[centres_pos], matched_y[centres_pos]


def split_large_cells(source, centres_x: np.ndarray, centres_y: np.ndarray, matched_x: np.ndarray,
                      matched_y: np.ndarray, x_idx: np.ndarray, max_cell: int) -> tuple[np.ndarray, np.ndarray]:
    """More centres until no geodesic Voronoi cell holds more than ``max_cell`` of the sample ``x_idx``: the
    largest cell gets a new centre at its matched vertex farthest from its centre (a farthest-point step
    inside that cell).

    Farthest points of the whole shape go to its extremities first, so on a shape with many protrusions a
    few centres leave the trunk to one cell, and an assignment's cost grows faster than its
    size. Returns the centres with the added ones at the end, (c',) each, distinct on both sides.
    """
    centres_x, centres_y = list(centres_x), list(centres_y)
    while True:
        labels, distances = voronoi_cells(source, np.asarray(centres_x))
        sizes = np.bincount(labels[x_idx], minlength=len(centres_x))
        largest = int(np.argmax(sizes))
        if sizes[largest] <= max_cell:
            break
        inside = (labels[matched_x] == largest) & ~np.isin(matched_x, centres_x) & ~np.isin(matched_y, centres_y)
        if not inside.any():
            break
        far = np.flatnonzero(inside)[np.argmax(distances[matched_x[inside]])]
        centres_x.append(int(matched_x[far]))
        centres_y.append(int(matched_y[far]))
    return np.asarray(centres_x, dtype=np.int64), np.asarray(centres_y, dtype=np.int64)


def transferred_cells(source, target, centres_x, centres_y, x_idx, y_idx, overlap: float, matched_x, matched_y):
    """Geodesic Voronoi cells of the source sample ``x_idx`` around ``centres_x``, and their target cells.

    A target cell holds the Voronoi cell of the sample ``y_idx`` around the centre's image ``centres_y``, widened
    across its borders by about ``overlap × √area / 2``, and every target vertex within that width of the current
    partner of one of the source cell's rows (the partner of the row's nearest matched vertex, ``matched_x`` →
    ``matched_y``). The Voronoi cells of the two shapes are transferred through the centres only, and where the
    shapes differ in pose their borders part by more than the overlap (at a joint): a row near such a border would
    find no partner near its own in its target cell and take the best one anywhere in it. Through the current
    map every row can reach the neighbourhood of its partner. Returns two lists of index arrays, one entry per
    centre.
    """
    lab_x, _ = voronoi_cells(source, centres_x)
    margin = overlap * np.sqrt(target.area)
    _, band_y = voronoi_bands(target, centres_y, margin)  # each border widened by about margin / 2
    x_cells = [x_idx[lab_x[x_idx] == cid] for cid in range(centres_x.size)]
    partner = nearest_partners(source, matched_x, matched_y)
    in_y = np.zeros(target.n_vertices, dtype=bool)
    in_y[y_idx] = True
    y_cells = []
    for rows, members in zip(x_cells, band_y):
        partners = np.unique(partner[rows][partner[rows] >= 0])
        if partners.size:
            near = dijkstra(target.adjacency, directed=False, indices=partners, limit=margin / 2, min_only=True)
            members = np.union1d(members, np.flatnonzero(np.isfinite(near)))
        y_cells.append(members[in_y[members]])
    return x_cells, y_cells


def multiscale_refinement(state: KernelState):
    """Stage 6 (§8.3.2): grow the vertex sample by ``growth`` per scale until every vertex is included; at
    each scale run ``passes`` refinement passes, each solving Voronoi cells (:func:`cell_centres`,
    :func:`split_large_cells`, :func:`transferred_cells`, :func:`_solve_cells`) at the smallest time with all
    current matches as anchors.

    There is always at least one finer scale (the seeds are surface points); its first pass takes the seeds'
    matches (interpolated eigenfunctions) as anchors. Landmarks stay matched: their vertices and partners are
    left out of the cells (and the cells are centred on the other matches). The source sample grows to at
    most the target's vertex count (:func:`surplus_partners` places the rest). A generator; returns
    ``map_xy`` (n_x,) and ``map_yx`` (n_y,) of the last pass (-1: unmatched).
    """
    params, source, target, watch = state.params, state.source, state.target, state.watch
    n_x, n_y, psi, phi = state.n_x, state.n_y, state.psi, state.phi
    rows_y, rows_x = state.problem.psi_s[state.seed_map], state.problem.phi_s  # eigenfunctions at the matches
    matched_x = state.seeds_x.nearest_corners(source)  # vertices of the matches (cell centres)
    matched_y = state.seeds_y.nearest_corners(target)[state.seed_map]
    state.seed_vertices_x, state.seed_vertices_y = matched_x.copy(), matched_y.copy()
    decay_y, decay_x = state.decays(state.taus[-1])
    mass_y = state.spec_y.mass.diagonal()
    landmark_x, landmark_y = np.zeros(n_x, dtype=bool), np.zeros(n_y, dtype=bool)
    landmark_x[state.anchors_x], landmark_y[state.anchors_y] = True, True
    size, last = state.n_seed, False
    keys, cell_map, cell_map_yx = np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), -np.ones(n_y, np.int64)
    # a source with more vertices than the target is sampled up to the target's count (partial matching
    # decides every vertex by the slack)
    top_x = n_x if params.partial else min(n_x, n_y)
    while not last:
        size = int(min(max(top_x, n_y), np.ceil(size * params.growth)))
        last = size >= max(top_x, n_y)
        x_idx, y_idx = state.order_x[:min(size, top_x)], state.order_y[:size]
        x_idx, y_idx = x_idx[~landmark_x[x_idx]], y_idx[~landmark_y[y_idx]]
        if x_idx.size == 0 or y_idx.size == 0 or landmark_x[matched_x].all():
            continue
        capacity_y = None
        if params.capacity == "area":
            capacity_y = np.ones(n_y, dtype=np.int64)
            capacity_y[y_idx] = area_capacities(x_idx.size, sample_masses(target, mass_y, y_idx))
        for p in range(params.passes):
            state.token.raise_if_cancelled()
            with watch("kernels"):
                c = alignment(rows_y, rows_x) + state.problem.anchor_c
            n_cells = max(1, int(np.ceil(x_idx.size / (CELL_FILL * params.max_cell))))
            free = ~landmark_x[matched_x]
            centres_x, centres_y = cell_centres(source.vertices, matched_x[free], matched_y[free], n_cells, p)
            centres_x, centres_y = split_large_cells(source, centres_x, centres_y, matched_x[free],
                                                     matched_y[free], x_idx, params.max_cell)
            with watch("cells"):
                x_cells, y_cells = transferred_cells(source, target, centres_x, centres_y, x_idx, y_idx,
                                                     params.cell_overlap, matched_x, matched_y)
            with watch("assignment"):
                cell_map, cell_map_yx = _solve_cells(x_cells, y_cells, psi, phi, c, decay_y, decay_x, params,
                                                     state.cancel, n_y, capacity_y)
            keys = np.concatenate(x_cells)
            ok = cell_map >= 0
            matched_x, matched_y = keys[ok], cell_map[ok]
            rows_y, rows_x = psi[matched_y], phi[matched_x]
            yield Progress("multiscale", PROGRESS_MULTISCALE[0] + PROGRESS_MULTISCALE[1] * size / max(n_x, n_y),
                           f"{size} samples, pass {p + 1}/{params.passes}: {centres_x.size} cells")
    full_map_xy = -np.ones(n_x, dtype=np.int64)
    full_map_xy[keys] = cell_map
    if top_x < n_x:
        surplus_partners(source, full_map_xy, keys, state.anchors_x)
    full_map_xy[state.anchors_x] = state.anchors_y
    cell_map_yx[state.anchors_y] = state.anchors_x
    return full_map_xy, cell_map_yx
