"""Load (or compile) every numba kernel once on tiny inputs.

The first call of a numba function loads its machine code from the on-disk
cache, or compiles it, holding the GIL. The studio calls :func:`warm_up` in
a background thread while it is idle after start-up, so the first real solve
neither pays that time nor freezes the window for it.
"""

from __future__ import annotations

import numpy as np


def warm_up() -> None:
    """Run each compiled kernel once on a tiny problem."""
    import scipy.sparse as sp

    from corrlib.assignment import linear_assignment
    from corrlib.deformation.basis import DivFreeBasis
    from corrlib.deformation.flow import flow, flow_with_jacobian
    from corrlib.deformation.mixture import mixture_moments
    from corrlib.descriptors.shot import shot
    from corrlib.geometry.cholesky import CholeskySolver
    from corrlib.geometry.cyclic_paths import ProductGraph, branch_and_bound
    from corrlib.geometry.elastic_paths import ElasticProductGraph
    from corrlib.geometry.geodesics import GeodesicSolver
    from corrlib.geometry.lifting import closest_surface_points
    from corrlib.geometry.sampling import farthest_point_sampling
    from corrlib.geometry.segmentation import persistent_protrusions
    from corrlib.methods.contour3d import node_costs
    from corrlib.neighbours import descended_nearest_rows
    from corrlib.progress import run
    from corrlib.shapes import TriMesh

    rng = np.random.default_rng(0)
    for dtype in (np.float64, np.float32):
        prices = np.zeros(4)
        first = linear_assignment(rng.random((4, 4)).astype(dtype), prices=prices)
        linear_assignment(rng.random((4, 4)).astype(dtype), prices=prices, warm_map=first)  # a warm start's gap
    t = np.linspace(0, 2 * np.pi, 6, endpoint=False)
    ring = np.column_stack([np.cos(t), np.sin(t), np.zeros(6)])
    adj = sp.coo_matrix((np.ones(6), (np.arange(6), (np.arange(6) + 1) % 6)), shape=(6, 6))
    cost = node_costs(rng.random((5, 3)), rng.random((6, 3)))
    run(branch_and_bound(ProductGraph(cost, ring[:5, :2], ring, adj)))
    # contour3d's elastic energies (energy=elastic / elastic-ratio, offered in the studio's form)
    run(branch_and_bound(ElasticProductGraph(cost, ring[:5, :2], ring, adj, stretch=0.1, bending=0.1)))
    sphere_v = np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0], [0, 0, -1]], float)
    sphere_f = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1], [5, 2, 1], [5, 3, 2], [5, 4, 3], [5, 1, 4]])
    sphere = TriMesh(sphere_v, sphere_f, validate=False)
    shot(sphere.vertices, sphere.faces, radius=2.0, min_neighbors=1)  # a mesh's arrays are read-only
    farthest_point_sampling(rng.random((6, 3)), 3)
    closest_surface_points(rng.random((3, 3)), sphere, np.array([[0, 1], [2, 3], [4, 5]]))
    persistent_protrusions(rng.random(6), adj, 0.1)
    ring_graph = (adj + adj.T).tocsr()
    descended_nearest_rows(rng.random((6, 3)), rng.random((6, 3)), np.arange(6), ring_graph.indptr,
                           ring_graph.indices)
    path_graph = sp.diags([-1.0, 2.5, -1.0], [-1, 0, 1], shape=(8, 8), format="csc")
    CholeskySolver(path_graph).solve(rng.random((8, 2)))
    GeodesicSolver(sphere).pair_distances(np.arange(3), np.arange(3, 6))
    # divergence-free: the flow (dense maps, morphs), the flow with float32 derivatives and the E-step (EM)
    basis = DivFreeBasis(6)
    cube_points = 0.25 + 0.5 * rng.random((4, 3))
    flow(basis, cube_points, 0.01 * rng.random(6), n_steps=2)
    flow_with_jacobian(basis, cube_points, 0.01 * rng.random(6), n_steps=2, dtype=np.float32)
    mixture_moments(cube_points, cube_points[::-1], 0.01, 0.1, rng.random((4, 4)), 0.5)
    # retrieval's view dissimilarity: a rendered outline and the inner-distance shape context of a drawing
    from corrlib.descriptors.shape_context import inner_shape_context, outline_dissimilarity
    from corrlib.geometry.sections import rendered_view

    rendered_view(sphere, np.array([0.0, 0.0, 1.0]), 32)
    notched = np.array([[0, 0], [4, 0], [4, 3], [2.5, 3], [2, 1], [1.5, 3], [0, 3]], float)  # a U: some chords blocked
    context = inner_shape_context(notched)
    outline_dissimilarity(context, context)
