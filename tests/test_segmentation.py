"""Protrusions by heat-kernel persistence: a hand-computed filtration, invariances on real shapes, the part
assignment against brute force, and the part term of 2D-to-3D matching."""

import itertools

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linear_sum_assignment

from corrlib.errors import ParameterError
from corrlib.geometry.laplacian import mesh_laplacian
from corrlib.geometry.segmentation import (assign_parts, heat_signature, part_costs, persistent_protrusions,
                                           protrusion_parts)
from corrlib.geometry.spectrum import eigenpairs, mesh_spectrum
from corrlib.geometry.triangulate import fill_contour
from corrlib.io import load_mesh, load_vts
from corrlib.methods import solve
from corrlib.methods.contour3d import Contour3DParams, part_cost, prepare_mesh, prepare_query
from corrlib.resources import resource
from corrlib.shapes import Contour2D, TriMesh
from tests._data import TOSCA


def path_graph(n):
    i = np.arange(n - 1)
    return sp.coo_matrix((np.ones(n - 1), (i, i + 1)), shape=(n, n)).tocsr() + \
        sp.coo_matrix((np.ones(n - 1), (i + 1, i)), shape=(n, n)).tocsr()


def agreement(a, b):
    """Share of points in the same part after the best one-to-one relabelling of the parts (a partition
    distance: 1 for equal partitions)."""
    table = np.zeros((a.max() + 1, b.max() + 1))
    np.add.at(table, (a, b), 1)
    rows, cols = linear_sum_assignment(-table)
    return table[rows, cols].sum() / a.shape[0]


def mesh_parts(mesh, k=30):
    spectrum = mesh_spectrum(mesh, k)
    return protrusion_parts(spectrum.evals, spectrum.evecs, mesh.adjacency, mesh.area).labels


def test_the_filtration_of_a_path_by_hand():
    """Two peaks (1.0 at vertex 2, 0.8 at vertex 8) and a bump (0.35 at vertex 5, 0.05 above its saddle).
    Threshold 0.1 x range 0.9 = 0.09: the bump joins the first peak's component at vertex 4; the two
    significant components meet at vertex 6, where both become parts; the rest is body."""
    f = np.array([0.1, 0.5, 1.0, 0.5, 0.3, 0.35, 0.3, 0.6, 0.8, 0.6, 0.1])
    labels = persistent_protrusions(f, path_graph(f.size), 0.1)
    assert labels.tolist() == [0, 1, 1, 1, 1, 1, 0, 2, 2, 2, 0]
    # a threshold above the bump's and the second peak's persistence (0.8 - 0.3 = 0.5 of range 0.9): no parts
    assert persistent_protrusions(f, path_graph(f.size), 0.6).tolist() == [0] * f.size
    # persistence 0: the bump is a third part (it meets the first peak at vertex 4, where both are significant)
    fine = persistent_protrusions(f, path_graph(f.size), 0.0)
    assert fine.max() == 3 and fine[5] == 3 and fine[4] == 0


def reference_protrusions(signature: np.ndarray, adjacency: sp.spmatrix, persistence: float) -> np.ndarray:
    """The filtration written plainly in Python (sets and lists): an independent reference."""
    f = np.asarray(signature, dtype=np.float64)
    n = f.shape[0]
    if not 0.0 <= persistence < 1.0:
        raise ValueError(f"persistence must be in [0, 1), got {persistence!r}")
    graph = sp.csr_matrix(adjacency)
    indptr, indices = graph.indptr, graph.indices
    threshold = persistence * float(f.max() - f.min())
    parent = np.full(n, -1, dtype=np.int64)
    peak = np.zeros(n)
    members: dict[int, list[int]] = {}  # vertices of a component that has not yet met a significant other
    parts: list[list[int]] = []

    def root(x: int) -> int:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for v in np.argsort(-f, kind="stable"):
        v = int(v)
        roots = {root(int(u)) for u in indices[indptr[v]:indptr[v + 1]] if parent[u] >= 0}
        parent[v] = v
        if not roots:  # a new maximum
            peak[v] = f[v]
            members[v] = [v]
            continue
        significant = [r for r in roots if peak[r] - f[v] > threshold]
        if len(significant) >= 2:  # two protrusions meet at a saddle: each is a part, up to here
            for r in significant:
                if r in members:
                    parts.append(members.pop(r))
        top = max(roots, key=lambda r: peak[r])
        still_open = all(r in members for r in roots)
        merged = [x for r in roots for x in members.pop(r, [])]
        for r in roots:
            parent[r] = top
        parent[v] = top
        if still_open:
            members[top] = merged + [v]
    labels = np.zeros(n, dtype=np.int64)
    for index, part in enumerate(sorted(parts, key=lambda p: -f[p].max())):
        labels[part] = index + 1
    return labels


@pytest.mark.parametrize("seed", range(6))
def test_protrusions_equal_a_plain_reference_on_random_graphs_and_a_real_shape(seed):
    """The compiled filtration against the plain one: random geometric graphs with random functions at
    several thresholds, and the heat signature of cat0 (the real case)."""
    rng = np.random.default_rng(seed)
    n = 300
    points = rng.random((n, 2))
    close = np.linalg.norm(points[:, None] - points[None], axis=2) < 0.09
    np.fill_diagonal(close, False)
    graph = sp.csr_matrix(close.astype(float))
    f = np.sin(6 * points[:, 0] + seed) * np.cos(5 * points[:, 1]) + 0.1 * rng.random(n)
    for persistence in (0.0, 0.05, 0.2):
        np.testing.assert_array_equal(persistent_protrusions(f, graph, persistence),
                                      reference_protrusions(f, graph, persistence))
    if seed == 0:
        cat = load_mesh(TOSCA / "cat0.off")
        spectrum = mesh_spectrum(cat, 30)
        parts = protrusion_parts(spectrum.evals, spectrum.evecs, cat.adjacency, cat.area)
        np.testing.assert_array_equal(parts.labels, reference_protrusions(parts.signature, cat.adjacency, 0.1))
        assert parts.n_parts >= 4


def test_heat_signature_is_the_diagonal_of_the_heat_kernel():
    rng = np.random.default_rng(1)
    evals = np.sort(rng.uniform(0, 10, 6))
    evecs = rng.normal(size=(9, 6))
    kernel = evecs @ np.diag(np.exp(-0.3 * evals)) @ evecs.T
    assert np.allclose(heat_signature(evals, evecs, 0.3), np.diag(kernel))


def plus_shape(arms=(3.0, 3.0, 3.0, 3.0), width=1.0):
    """A plus sign (2D outline) with arms to the right, up, left and down of the given lengths."""
    h = width / 2
    r, u, l, d = (h + a for a in arms)
    return np.array([(h, h), (r, h), (r, -h), (h, -h), (h, -d), (-h, -d), (-h, -h), (-l, -h), (-l, h), (-h, h),
                     (-h, u), (h, u)])


def filled_parts(points):
    contour = Contour2D(points, validate=False).resample(160)
    filled = fill_contour(contour)
    stiffness, mass = mesh_laplacian(filled)
    evals, evecs = eigenpairs(stiffness, mass, 30)
    return filled, protrusion_parts(evals, evecs, filled.adjacency, contour.area)


def arm_shares(filled, parts, directions):
    """For every direction, the share of the vertices in the part of the arm tip farthest that way."""
    tips = [int(np.argmax(filled.vertices[:, :2] @ d)) for d in directions]
    return np.array([np.mean(parts.labels == parts.labels[tip]) for tip in tips]), parts.labels[tips]


def test_a_plus_sign_has_four_arms_and_a_body():
    filled, parts = filled_parts(plus_shape())
    assert parts.n_parts == 4
    directions = np.array([[1, 0], [0, 1], [-1, 0], [0, -1]])
    _, tip_labels = arm_shares(filled, parts, directions)
    assert sorted(tip_labels.tolist()) == [1, 2, 3, 4]
    assert parts.labels[np.argmin(np.linalg.norm(filled.vertices, axis=1))] == 0
    for tip_label, direction in zip(tip_labels, directions):  # every arm's part lies in its arm
        assert np.all(filled.vertices[parts.labels == tip_label, :2] @ direction > 0)


def test_parts_do_not_depend_on_units_rotation_or_point_order():
    """The time is in units of the area and the threshold relative to the signature's range: scaled,
    rotated and reversed outlines (each triangulated anew) give arms of the same share."""
    points = plus_shape(arms=(3.0, 2.0, 2.5, 1.5))
    directions = np.array([[1, 0], [0, 1], [-1, 0], [0, -1]], dtype=float)
    filled, parts = filled_parts(points)
    shares, labels = arm_shares(filled, parts, directions)
    assert parts.n_parts == 4 and sorted(labels.tolist()) == [1, 2, 3, 4]
    angle = 0.7
    rotation = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    for moved, moved_directions in ((points * 25.0, directions), (points @ rotation.T, directions @ rotation.T),
                                    (points[::-1], directions)):
        other, other_parts = filled_parts(moved)
        other_shares, other_labels = arm_shares(other, other_parts, moved_directions)
        assert other_parts.n_parts == 4
        assert sorted(other_labels.tolist()) == [1, 2, 3, 4]  # one part per arm (their order is by peak height)
        assert np.max(np.abs(other_shares - shares)) < 0.02


def test_the_parts_of_a_shape_survive_its_poses_mirror_image_noise_and_vertex_order():
    cat0, cat1 = load_mesh(TOSCA / "cat0.off"), load_mesh(TOSCA / "cat1.off")
    parts0, parts1 = mesh_parts(cat0), mesh_parts(cat1)
    assert parts0.max() == parts1.max() == 6  # four legs, the head and the tail
    assert agreement(parts0[load_vts(TOSCA / "cat0.vts")], parts1[load_vts(TOSCA / "cat1.vts")]) > 0.9
    people = [load_mesh(resource(f"people/human{i}.off")) for i in range(4)]  # one connectivity
    labels = [mesh_parts(person) for person in people]
    assert all(lab.max() == 5 for lab in labels)  # head, arms, legs
    assert min(agreement(labels[0], lab) for lab in labels[1:]) > 0.95
    mirrored = TriMesh(people[1].vertices * [-1.0, 1.0, 1.0], people[1].faces[:, ::-1])
    assert agreement(labels[1], mesh_parts(mirrored)) > 0.99
    perm = np.random.default_rng(0).permutation(cat0.n_vertices)
    shuffled = TriMesh(cat0.vertices[perm] * 7.3, np.argsort(perm)[cat0.faces])
    assert agreement(parts0, mesh_parts(shuffled)[np.argsort(perm)]) > 0.99
    noise = np.random.default_rng(1).normal(0.0, 0.002 * cat0.bbox_diagonal, cat0.vertices.shape)
    assert agreement(parts0, mesh_parts(TriMesh(cat0.vertices + noise, cat0.faces))) > 0.95


def test_part_costs_and_assignment_against_brute_force():
    rng = np.random.default_rng(4)
    for _ in range(20):
        m, n, pa, pb = 12, 15, int(rng.integers(1, 4)), int(rng.integers(1, 4))
        cost = rng.uniform(0, 1, (m, n))
        la = np.concatenate([np.arange(pa + 1), rng.integers(0, pa + 1, m - pa - 1)])
        lb = np.concatenate([np.arange(pb + 1), rng.integers(0, pb + 1, n - pb - 1)])
        table = part_costs(cost, la, lb)
        for a, b in itertools.product(range(pa + 1), range(pb + 1)):
            assert table[a, b] == pytest.approx(cost[np.ix_(la == a, lb == b)].mean())
        mapped = assign_parts(cost, la, lb)
        assert np.all(mapped[la == 0] == 0)
        chosen = {a: int(mapped[la == a][0]) for a in range(1, pa + 1)}
        assert sum(v > 0 for v in chosen.values()) == min(pa, pb)
        assert len({v for v in chosen.values() if v > 0}) == min(pa, pb)  # one to one
        total = sum(table[a, b] for a, b in chosen.items() if b > 0)
        best = min(sum(table[a, b] for a, b in zip(rows, cols))
                   for rows in itertools.permutations(range(1, pa + 1), min(pa, pb))
                   for cols in itertools.permutations(range(1, pb + 1), min(pa, pb)))
        assert total == pytest.approx(best)


def test_bad_segmentation_parameters_are_named():
    with pytest.raises(ParameterError, match="persistence"):
        persistent_protrusions(np.zeros(3), path_graph(3), 1.5)
    with pytest.raises(ParameterError, match="time"):
        protrusion_parts(np.zeros(2), np.ones((3, 2)), path_graph(3), 1.0, time=0.0)


@pytest.fixture(scope="module")
def wolf_silhouette():
    from corrlib.contour_bench import silhouette_query

    wolf0, wolf1 = load_mesh(TOSCA / "wolf0.off"), load_mesh(TOSCA / "wolf1.off")
    return silhouette_query(wolf0).contour, wolf1


def test_the_part_term_charges_only_points_of_different_matched_parts(wolf_silhouette):
    contour, wolf1 = wolf_silhouette
    params = Contour3DParams(parts="auto", n_contour=60)
    query, mesh = prepare_query(contour, params), prepare_mesh(wolf1, params)
    assert query.parts.max() >= 3 and mesh.parts.max() == 6  # legs, head, tail on both
    cost = np.random.default_rng(0).uniform(0, 1, (query.parts.size, mesh.parts.size))
    term = part_cost(query, mesh, cost, 2.0, params)
    as_mesh = assign_parts(cost, query.parts, mesh.parts)
    assert set(np.unique(term)) <= {0.0, 2.0}
    for i in range(0, query.parts.size, 7):
        expected = np.where((as_mesh[i] >= 0) & (mesh.parts != as_mesh[i]), 2.0, 0.0)
        assert np.array_equal(term[i], expected)
    assert part_cost(query, mesh, cost, 2.0, Contour3DParams(parts="auto", part_weight=0.0)) == 0.0


def test_user_labels_replace_the_automatic_parts(wolf_silhouette):
    contour, wolf1 = wolf_silhouette
    contour = contour.resample(60)
    labelled = Contour2D(contour.points, labels=np.where(contour.points[:, 0] > contour.points[:, 0].mean(), 1, 2))
    axis = np.linalg.svd(wolf1.vertices - wolf1.vertices.mean(0), full_matrices=False)[2][0]
    mesh = wolf1.with_labels(np.where((wolf1.vertices - wolf1.vertices.mean(0)) @ axis > 0, 1, 2))
    with_parts = solve("contour3d", labelled, mesh, n_contour=60, eps=0.05, parts="auto")
    without = solve("contour3d", labelled, mesh, n_contour=60, eps=0.05, parts="none")
    assert with_parts.energy == pytest.approx(without.energy)
    assert np.array_equal(with_parts.map_xy, without.map_xy)
