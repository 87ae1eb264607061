"""Decimation to a vertex budget (corrlib.geometry.remeshing)."""

import numpy as np
import pytest
import trimesh

from corrlib.geometry.remeshing import remeshed
from corrlib.shapes import TriMesh


@pytest.fixture(scope="module")
def sphere():
    ico = trimesh.creation.icosphere(subdivisions=5, radius=2.0)  # 10,242 vertices
    return TriMesh(ico.vertices, ico.faces, name="sphere")


def test_a_coarser_mesh_is_subdivided_then_remeshed_on_the_same_surface():
    """A mesh coarser than the budget is subdivided at its edge midpoints (the same piecewise-linear surface)
    past the budget and then decimated: the result has the budget's vertices and lies on the input surface."""
    from scipy.spatial import cKDTree

    ico = trimesh.creation.icosphere(subdivisions=3, radius=2.0)  # 642 vertices
    coarse_sphere = TriMesh(ico.vertices, ico.faces, name="coarse sphere")
    result = remeshed(coarse_sphere, 2000)
    # fewer by the coincident vertices merged on flat regions (the subdivision's)
    assert 0.95 * 2000 <= result.mesh.n_vertices <= 2020 and result.n_original == 642
    # on the input surface, up to the input's chord sagitta (the relaxation projects onto tangent planes)
    radius = np.linalg.norm(result.mesh.vertices, axis=1)
    sagitta = 2.0 - np.min(np.linalg.norm(ico.triangles_center, axis=1))
    assert np.all(np.abs(radius - 2.0) <= sagitta)
    assert result.mesh.area == pytest.approx(coarse_sphere.area, rel=0.01)
    nearest = cKDTree(coarse_sphere.vertices).query(result.mesh.vertices)[1]
    assert np.array_equal(result.to_original, nearest)
    # a mesh at the budget is remeshed too (one triangulation for every mesh), to its own vertex count
    again = remeshed(coarse_sphere, 642)
    assert 0.95 * 642 <= again.mesh.n_vertices <= 649


def test_the_remeshing_does_not_depend_on_the_order_of_vertices_and_faces(sphere):
    """Quadric collapse breaks ties of equal cost by the input's order; the surface is put in a canonical
    order first, so a shuffled copy (vertices, faces, and each face's rotation) gives the same mesh."""
    rng = np.random.default_rng(3)
    perm = rng.permutation(sphere.n_vertices)
    faces = np.argsort(perm)[sphere.faces][rng.permutation(sphere.n_faces)]
    faces = np.take_along_axis(faces, (rng.integers(0, 3, len(faces))[:, None] + np.arange(3)) % 3, axis=1)
    shuffled = TriMesh(sphere.vertices[perm], faces, name="shuffled")
    base, other = remeshed(sphere, 3000), remeshed(shuffled, 3000)
    assert np.array_equal(base.mesh.vertices, other.mesh.vertices)
    assert np.array_equal(base.mesh.faces, other.mesh.faces)
    assert np.array_equal(perm[other.to_original], base.to_original)


def test_the_decimated_sphere_keeps_its_surface_and_topology(sphere):
    coarse = remeshed(sphere, 2000)
    mesh = coarse.mesh
    assert coarse.n_original == sphere.n_vertices
    assert abs(mesh.n_vertices - 2000) <= 20
    # a closed genus-0 surface stays one: V - E + F = 2, every edge in two faces
    edges = np.sort(mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    unique_edges, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)
    assert mesh.n_vertices - len(unique_edges) + mesh.n_faces == 2
    # on the sphere of radius 2, with its area (4π · 4) within the chord error of ~2000 vertices
    assert np.allclose(np.linalg.norm(mesh.vertices, axis=1), 2.0, atol=0.01)
    assert mesh.area == pytest.approx(16 * np.pi, rel=0.01)


def test_every_decimated_vertex_points_to_its_nearest_input_vertex(sphere):
    coarse = remeshed(sphere, 1000)
    distances = np.linalg.norm(coarse.mesh.vertices[:, None, :] - sphere.vertices[None, :, :], axis=2)
    chosen = np.linalg.norm(coarse.mesh.vertices - sphere.vertices[coarse.to_original], axis=1)
    assert np.allclose(chosen, distances.min(axis=1), rtol=0, atol=1e-12)  # the nearest, up to ties
    spacing = np.mean(np.linalg.norm(np.diff(sphere.vertices[sphere.faces[:, :2]], axis=1)[:, 0], axis=1))
    assert np.max(np.linalg.norm(coarse.mesh.vertices - sphere.vertices[coarse.to_original], axis=1)) < spacing


def test_part_labels_follow_the_nearest_input_vertex(sphere):
    labels = np.where(sphere.vertices[:, 0] > 0, 1, 2)
    coarse = remeshed(sphere.with_labels(labels), 1500)
    assert np.array_equal(coarse.mesh.labels, labels[coarse.to_original])
    away_from_the_border = np.abs(coarse.mesh.vertices[:, 0]) > 0.1
    expected = np.where(coarse.mesh.vertices[:, 0] > 0, 1, 2)
    assert np.array_equal(coarse.mesh.labels[away_from_the_border], expected[away_from_the_border])


def test_a_fin_and_coincident_vertices_are_removed(sphere):
    """A face folded onto its reverse (a fin) and a duplicated vertex are what edge collapse can leave."""
    from corrlib.geometry.remeshing import without_degenerate_faces

    a, b = sphere.faces[0, :2]
    tip = sphere.vertices[[a, b]].mean(axis=0) * 1.5
    points = np.vstack([sphere.vertices, tip, sphere.vertices[5]])  # the fin's tip; a copy of vertex 5
    faces = sphere.faces.copy()
    fan = np.flatnonzero((faces == 5).any(axis=1))[:3]  # half of vertex 5's faces use its copy: a seam
    faces[fan] = np.where(faces[fan] == 5, len(points) - 1, faces[fan])
    fin = len(points) - 2
    faces = np.vstack([faces, [[a, b, fin], [b, a, fin]]])
    repaired_points, repaired_faces = without_degenerate_faces(points, faces)
    mesh = TriMesh(repaired_points, repaired_faces, name="repaired")  # valid: raises otherwise
    assert mesh.n_vertices == sphere.n_vertices and mesh.n_faces == sphere.n_faces
    assert mesh.area == pytest.approx(sphere.area, rel=1e-12)


def test_a_needle_vertex_is_merged_into_its_neighbour(sphere):
    """A vertex 1e-5 of an edge from that edge's end (two needle triangles of almost no area, above the zero-area
    test, and 1e-7 of the diagonal apart, above exact coincidence) is one point with that end at the mesh's
    resolution: it is merged, and the surface is the sphere's."""
    from _data import with_needle_vertex
    from corrlib.geometry.remeshing import without_degenerate_faces

    points, faces = with_needle_vertex(sphere.vertices, sphere.faces, 1e-5)
    repaired_points, repaired_faces = without_degenerate_faces(points, faces)
    mesh = TriMesh(repaired_points, repaired_faces, name="repaired")
    assert mesh.n_vertices == sphere.n_vertices and mesh.n_faces == sphere.n_faces
    assert mesh.area == pytest.approx(sphere.area, rel=1e-9)


@pytest.mark.slow
def test_a_twice_subdivided_cat_is_remeshed_without_needles(tmp_path):
    """TOSCA cat1 subdivided twice at its edge midpoints and written to a file (80k vertices, quadruples of
    faces flat up to the file's rounding): the collapse left 55 needle triangles (shortest edge under 1e-7 of
    the longest), whose vertices made the remeshed cat read as disconnected. None is left, and the result is
    one connected surface of the budget's size."""
    from scipy.sparse.csgraph import connected_components

    from _data import TOSCA
    from corrlib.io import load_mesh, save_mesh

    cat = load_mesh(TOSCA / "cat1.off")
    fine = trimesh.Trimesh(cat.vertices, cat.faces, process=False).subdivide().subdivide()
    save_mesh(tmp_path / "fine-cat.off", fine.vertices, fine.faces)
    coarse = remeshed(load_mesh(tmp_path / "fine-cat.off"), 5000).mesh
    lengths = np.linalg.norm(coarse.vertices[coarse.faces] - coarse.vertices[np.roll(coarse.faces, 1, axis=1)],
                             axis=2)
    assert (lengths.min(axis=1) / lengths.max(axis=1)).min() > 1e-3
    assert connected_components(coarse.adjacency)[0] == 1
    assert 4950 <= coarse.n_vertices <= 5050


@pytest.mark.slow
def test_decimating_a_flat_subdivision_repairs_its_zero_area_faces():
    """Edge collapse on flat regions (a mesh subdivided at its edge midpoints) leaves faces of zero area;
    the decimated mesh has none, keeps the surface's genus and its area (to the chords' 1 %), and the vertex
    budget."""
    import fast_simplification

    from _data import TOSCA
    from corrlib.io import load_mesh
    from corrlib.shapes import inspect_mesh

    wolf = load_mesh(TOSCA / "wolf1.off")
    flat = trimesh.Trimesh(wolf.vertices, wolf.faces, process=False).subdivide()
    raw = fast_simplification.simplify(np.array(flat.vertices), np.array(flat.faces, dtype=np.int32),
                                       target_count=round(len(flat.faces) * 5000 / len(flat.vertices)))
    assert any(finding.code == "zero-area-face" for finding in inspect_mesh(*raw))  # what is repaired
    coarse = remeshed(TriMesh(flat.vertices, flat.faces, name="flat"), 5000).mesh
    assert 4500 < coarse.n_vertices <= 5000
    euler = lambda m: m.n_vertices - len(np.unique(np.sort(m.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1),
                                                   axis=0)) + m.n_faces
    assert euler(coarse) == euler(wolf)
    assert coarse.area == pytest.approx(wolf.area, rel=0.02)


def test_relaxation_evens_out_the_edges_and_stays_on_the_surface():
    """Quadric edge collapse leaves an adaptive mesh; the relaxed one has more even edges, the same
    connectivity, and its vertices on the input surface."""
    import fast_simplification
    from scipy.spatial import cKDTree

    from _data import TOSCA
    from corrlib.geometry.remeshing import tangentially_relaxed
    from corrlib.io import load_mesh

    wolf = load_mesh(TOSCA / "wolf1.off")
    fine = TriMesh(*trimesh.remesh.subdivide_loop(wolf.vertices, wolf.faces, iterations=1), name="fine")
    points, faces = fast_simplification.simplify(np.array(fine.vertices), np.array(fine.faces, dtype=np.int32),
                                                 target_count=6000)
    adaptive = TriMesh(points, faces, name="adaptive")
    relaxed = tangentially_relaxed(adaptive, fine)
    spread = lambda m: m.edge_lengths.std() / m.edge_lengths.mean()
    assert spread(relaxed) < 0.85 * spread(adaptive), (spread(relaxed), spread(adaptive))
    assert np.array_equal(relaxed.faces, adaptive.faces)
    # on the surface: within one of its faces of a surface vertex (the chords of the coarser mesh cut in)
    off_surface = cKDTree(fine.vertices).query(relaxed.vertices)[0]
    assert off_surface.max() < fine.edge_lengths.max() and off_surface.mean() < 0.5 * fine.edge_lengths.mean()
    assert relaxed.area == pytest.approx(fine.area, rel=0.02)


def test_a_decimation_is_cached_by_the_mesh_content(sphere, tmp_path, monkeypatch):
    from corrlib import cache

    monkeypatch.setenv("CORRLIB_CACHE_DIR", str(tmp_path))
    first = remeshed(sphere, 1200)
    assert len(list((tmp_path / "remeshed").glob("*.npz"))) == 1
    again = remeshed(TriMesh(sphere.vertices, sphere.faces, name="same surface"), 1200)  # read from the cache
    assert np.array_equal(again.mesh.vertices, first.mesh.vertices)
    assert np.array_equal(again.mesh.faces, first.mesh.faces) and np.array_equal(again.to_original, first.to_original)
    assert again.mesh.name.startswith("same surface")
    remeshed(sphere, 1300)  # another budget, another entry
    assert len(list((tmp_path / "remeshed").glob("*.npz"))) == 2
    assert cache.cache_dir() == tmp_path


def test_an_open_surface_keeps_its_boundary_and_its_area():
    """The relaxation keeps boundary vertices in place: the centroid of a boundary vertex's neighbours lies
    inside the surface, and moving towards it drew a hemisphere's rim in (6 % of its area, measured)."""
    ico = trimesh.creation.icosphere(subdivisions=4)
    half = ico.submesh([np.flatnonzero(ico.triangles_center[:, 2] > 0.0)], append=True)
    hemisphere = TriMesh(half.vertices, half.faces, name="hemisphere")

    def boundary_heights(mesh):
        edges = np.sort(mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
        unique_edges, counts = np.unique(edges, axis=0, return_counts=True)
        return mesh.vertices[np.unique(unique_edges[counts == 1]), 2]

    result = remeshed(hemisphere, 3000).mesh
    assert boundary_heights(result).max() <= boundary_heights(hemisphere).max() + 1e-9
    assert result.area == pytest.approx(hemisphere.area, rel=0.005)
