"""The geodesic distortion of a vertex map between two meshes (corrlib.geometry.distortion)."""

import numpy as np
import pytest
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial.transform import Rotation

from corrlib.geometry.distortion import GEODESIC_SAMPLES, geodesic_distortions
from corrlib.geometry.sampling import outermost_farthest_points
from corrlib.shapes import TriMesh


def blob(n_subdivisions: int = 3, seed: int = 0) -> TriMesh:
    """A lumpy sphere: no symmetry, no exact ties of distance."""
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=n_subdivisions)
    vertices = np.asarray(sphere.vertices)
    bumps = 1.0 + 0.2 * np.sin(3 * vertices[:, 0] + 1.0) * np.cos(2 * vertices[:, 1]) + 0.1 * vertices[:, 2] ** 3
    rng = np.random.default_rng(seed)
    vertices = vertices * bumps[:, None] * [1.4, 1.0, 0.8] + rng.normal(scale=1e-3, size=vertices.shape)
    return TriMesh(vertices, np.asarray(sphere.faces), name="blob")


def edge_graph_distances(mesh: TriMesh, sources: np.ndarray) -> np.ndarray:
    """Shortest edge paths by SciPy's Dijkstra on a graph built here from the faces (independent of
    corrlib.geometry.geodesics)."""
    edges = np.concatenate([mesh.faces[:, [0, 1]], mesh.faces[:, [1, 2]], mesh.faces[:, [2, 0]]])
    lengths = np.linalg.norm(mesh.vertices[edges[:, 0]] - mesh.vertices[edges[:, 1]], axis=1)
    graph = csr_matrix((lengths, (edges[:, 0], edges[:, 1])), shape=(mesh.n_vertices,) * 2)
    return dijkstra(graph, directed=False, indices=sources)


def test_distortion_equals_its_definition_by_brute_force():
    """D(m) = mean over sample pairs of |d_X(a, b)/√A_X − d_Y(m a, m b)/√A_Y|, with -1 leaving a sample out."""
    source, target = blob(seed=0), blob(seed=1)
    rng = np.random.default_rng(2)
    map_xy = rng.integers(0, target.n_vertices, source.n_vertices)
    map_xy[rng.random(source.n_vertices) < 0.2] = -1
    sample = outermost_farthest_points(source.vertices, GEODESIC_SAMPLES)
    matched = sample[map_xy[sample] >= 0]
    images = map_xy[matched]
    d_x = edge_graph_distances(source, matched)[:, matched] / np.sqrt(source.area)
    d_y = edge_graph_distances(target, images)[:, images] / np.sqrt(target.area)
    expected = np.mean(np.abs(d_x - d_y))
    assert geodesic_distortions(source, target, (map_xy,))[0] == pytest.approx(expected, rel=1e-10)


def test_an_isometry_up_to_scale_has_no_distortion_and_a_shuffle_has():
    """The identity onto a rotated, moved, scaled and renumbered copy is an isometry up to scale: zero. A
    random map is far from one; several maps at once equal one at a time."""
    source = blob()
    rng = np.random.default_rng(3)
    order = rng.permutation(source.n_vertices)
    inverse = np.argsort(order)
    moved = Rotation.from_rotvec([0.3, -1.2, 0.7]).apply(np.array(source.vertices)) * 250.0 + [1e3, -2e3, 5.0]
    copy = TriMesh(moved[order], inverse[source.faces], name="copy")
    identity_map = inverse  # vertex v of the source is vertex inverse[v] of the copy
    shuffled = rng.permutation(source.n_vertices)
    together = geodesic_distortions(source, copy, (identity_map, shuffled))
    assert together[0] < 1e-9
    assert together[1] > 0.2
    assert together == [geodesic_distortions(source, copy, (m,))[0] for m in (identity_map, shuffled)]


def test_a_map_with_fewer_than_two_samples_matched_has_no_distortion():
    source = blob()
    assert np.isnan(geodesic_distortions(source, source, (-np.ones(source.n_vertices, dtype=np.int64),))[0])


def capsule_surface() -> TriMesh:
    """A capsule along z (a surface of revolution: every rotation about z is an isometry of it)."""
    import trimesh

    capsule = trimesh.creation.capsule(height=2.0, radius=0.5, count=[24, 24])
    vertices, faces = trimesh.remesh.subdivide_to_size(capsule.vertices, capsule.faces, max_edge=0.15)
    return TriMesh(np.asarray(vertices), np.asarray(faces), name="capsule")


def test_a_map_turned_half_round_on_one_half_splits_at_the_seam():
    """The identity below z = 0 and the half turn about the axis above it: each half alone is an isometry, the
    distances across the seam are not kept. The split finds the two halves, and they disagree; the identity
    and the whole half turn (an isometry) do not split."""
    from scipy.spatial import cKDTree

    from corrlib.geometry.distortion import DISAGREEMENT_RATIO, inconsistent_parts

    mesh = capsule_surface()
    z = mesh.vertices[:, 2]
    _, turned = cKDTree(mesh.vertices).query(mesh.vertices * [-1.0, -1.0, 1.0])
    twisted = np.where(z > 0, turned, np.arange(mesh.n_vertices))
    parts = inconsistent_parts(mesh, mesh, twisted)
    assert parts.disagree and parts.ratio > DISAGREEMENT_RATIO, parts.ratio
    away = (np.abs(z) > 0.3) & (np.abs(z) < 1.0)  # near the seam, and near the poles that the turn keeps, either way
    agreement = np.mean(parts.part[away] == (z[away] > 0))
    assert max(agreement, 1 - agreement) > 0.97, agreement
    for whole in (np.arange(mesh.n_vertices), turned):
        assert not inconsistent_parts(mesh, mesh, whole).disagree


def test_parts_that_disagree_by_less_than_the_mesh_resolves_do_not_disagree():
    """The identity onto a copy with vertex noise of a tenth of an edge: the distortion within any split is
    nearly zero, so the ratio can be large, but the parts differ by less than the edge paths resolve."""
    from corrlib.geometry.distortion import RESOLVED_EDGES, inconsistent_parts

    mesh = capsule_surface()
    edge = np.mean(mesh.edge_lengths)
    rng = np.random.default_rng(1)
    noisy = TriMesh(mesh.vertices + rng.normal(scale=0.1 * edge, size=mesh.vertices.shape), mesh.faces, name="noisy")
    parts = inconsistent_parts(mesh, noisy, np.arange(mesh.n_vertices))
    assert parts.between < RESOLVED_EDGES * parts.resolution and not parts.disagree
    assert parts.resolution == pytest.approx(max(mesh.relative_edge_length, noisy.relative_edge_length))
    assert mesh.relative_edge_length == pytest.approx(edge / np.sqrt(mesh.area))
    scaled = TriMesh(mesh.vertices * 1000.0, mesh.faces, name="in millimetres")
    assert scaled.relative_edge_length == pytest.approx(mesh.relative_edge_length)


def test_inconsistent_parts_of_an_unmatched_map_is_none():
    from corrlib.geometry.distortion import inconsistent_parts

    mesh = capsule_surface()
    assert inconsistent_parts(mesh, mesh, -np.ones(mesh.n_vertices, dtype=np.int64)) is None


def test_sample_distortions_are_the_rows_whose_mean_is_the_distortion():
    """Each sample's mean distortion against the others; their mean is D(m), and the images' rows hold the
    distances between them."""
    from corrlib.geometry.distortion import PairDistances

    source, target = blob(seed=0), blob(seed=1)
    map_xy = np.random.default_rng(4).integers(0, target.n_vertices, source.n_vertices)
    distances = PairDistances(source, target)
    matched, values = distances.sample_distortions(map_xy)
    assert matched.size == GEODESIC_SAMPLES and values.shape == (GEODESIC_SAMPLES,)
    assert values.mean() == pytest.approx(geodesic_distortions(source, target, (map_xy,), distances)[0], rel=1e-12)
    images = map_xy[distances.sample]
    rows = distances.from_images(images)
    assert rows.shape == (GEODESIC_SAMPLES, target.n_vertices)
    expected = edge_graph_distances(target, images[:3])[:, images] / np.sqrt(target.area)
    assert np.allclose(distances.between_images(images)[:3], expected, rtol=1e-10)
