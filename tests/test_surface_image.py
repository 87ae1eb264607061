"""The image of a vertex map on the target's surface (corrlib.deformation.surface_image), the last frame of a
sequence through a map that is not one-to-one: faces, surface, distance to the partner, and invariances."""

import numpy as np
import pytest
import trimesh
from scipy.sparse.csgraph import shortest_path
from scipy.spatial import cKDTree

from corrlib.deformation.surface_image import (CANDIDATE_RINGS, collapsed_or_turned, image_on_surface,
                                               nearest_candidates, ring_neighbourhoods)
from corrlib.shapes import TriMesh, triangle_areas


def normals(points, faces):
    return np.cross(points[faces[:, 1]] - points[faces[:, 0]], points[faces[:, 2]] - points[faces[:, 0]])


@pytest.fixture(scope="module")
def snapped(wolf_pair):
    """The wolves' true map (they share connectivity) snapped to half of wolf1's vertices: every source vertex
    sent to the nearest of them, as a map that resolves half the detail does (kernel matching reaches 3,430 of
    the cats' 5,000 vertices)."""
    from corrlib.geometry.sampling import farthest_point_sampling

    wolf0, wolf1 = wolf_pair
    kept = farthest_point_sampling(wolf1.vertices, wolf1.n_vertices // 2)
    return kept[cKDTree(wolf1.vertices[kept]).query(wolf1.vertices)[1]]


def test_ring_neighbourhoods_and_candidates_against_brute_force():
    mesh = trimesh.creation.icosphere(subdivisions=2)
    target = TriMesh(mesh.vertices, mesh.faces)
    hops = shortest_path(target.adjacency, unweighted=True)
    for rings in (0, 1, 2):
        assert np.array_equal(ring_neighbourhoods(target.adjacency, rings).toarray() > 0, hops <= rings)
    rng = np.random.default_rng(3)
    points = target.vertices[rng.integers(0, target.n_vertices, 40)] + 0.05 * rng.normal(size=(40, 3))
    partners = rng.integers(0, target.n_vertices, 40)
    chosen = nearest_candidates(points, target.vertices, partners, ring_neighbourhoods(target.adjacency, 2), 4)
    for point, partner, row in zip(points, partners, chosen):
        near = np.flatnonzero(hops[partner] <= 2)
        best = near[np.argsort(np.linalg.norm(target.vertices[near] - point, axis=1))[:4]]
        assert np.array_equal(np.sort(row), np.sort(best))


def test_a_map_that_sends_neighbours_to_one_vertex_lands_without_collapsed_faces(wolf_pair, snapped):
    """Half the faces of the snapped map's vertex image have no area; on the surface none is left (measured
    0.05 %), and a few are turned over (1.6 %, against none of the truth's). Every vertex lies on wolf1's surface
    (checked by trimesh's brute-force closest point), within the two rings of its partner, and on average
    nearer its true place than its partner is (0.19 against 0.21 of an edge)."""
    from corrlib.methods.base import MatchResult
    from corrlib.morph import frame_positions, map_image

    wolf0, wolf1 = wolf_pair
    image = map_image(wolf0, wolf1.vertices, snapped)
    landed = image_on_surface(wolf0, wolf1, snapped, image)
    true_areas = triangle_areas(wolf1.vertices, wolf0.faces)
    assert np.mean(triangle_areas(image, wolf0.faces) < 1e-3 * true_areas) > 0.4
    assert np.mean(triangle_areas(landed, wolf0.faces) < 1e-3 * true_areas) < 0.005
    assert np.mean(np.einsum("ij,ij->i", normals(landed, wolf0.faces), wolf1.face_normals) < 0) < 0.03
    sample = np.random.default_rng(0).choice(wolf0.n_vertices, 300, replace=False)
    surface = trimesh.Trimesh(wolf1.vertices, wolf1.faces, process=False)
    distance = trimesh.proximity.closest_point_naive(surface, landed[sample])[1]
    assert distance.max() < 1e-9 * wolf1.bbox_diagonal
    reach = (CANDIDATE_RINGS + 1) * wolf1.edge_lengths.max()  # a face in the star of a vertex two rings away
    assert np.linalg.norm(landed - image, axis=1).max() <= reach
    assert np.linalg.norm(landed - wolf1.vertices, axis=1).mean() < np.linalg.norm(image - wolf1.vertices,
                                                                                  axis=1).mean()
    last = frame_positions(MatchResult("descriptor-nn", snapped, None), wolf0, wolf1, [1.0])[0]
    assert np.allclose(last, landed, atol=1e-6)  # the sequence through the map ends there


def test_the_landing_follows_vertex_order_mirror_images_and_units(wolf_pair, snapped):
    """The source's vertices shuffled, both shapes mirrored (faces rewound) or both in other units: the same
    landing, shuffled, mirrored or scaled with them."""
    from corrlib.morph import map_image

    wolf0, wolf1 = wolf_pair

    def landing(source, target, map_xy):
        return image_on_surface(source, target, map_xy, map_image(source, target.vertices, map_xy))

    landed = landing(wolf0, wolf1, snapped)
    order = np.random.default_rng(5).permutation(wolf0.n_vertices)
    shuffled = TriMesh(wolf0.vertices[order], np.argsort(order)[wolf0.faces])
    assert np.allclose(landing(shuffled, wolf1, snapped[order]), landed[order], atol=1e-9)
    flip = np.array([-1.0, 1.0, 1.0])
    mirrored = landing(TriMesh(wolf0.vertices * flip, wolf0.faces[:, ::-1]),
                       TriMesh(wolf1.vertices * flip, wolf1.faces[:, ::-1]), snapped)
    assert np.allclose(mirrored * flip, landed, atol=1e-9)
    scaled = landing(TriMesh(wolf0.vertices * 1000.0, wolf0.faces), TriMesh(wolf1.vertices * 1000.0, wolf1.faces),
                     snapped)
    assert np.allclose(scaled / 1000.0, landed, atol=1e-9)


def test_only_faces_the_map_collapses_or_turns_are_moved(wolf_pair):
    """The identity between two registrations keeps every vertex where it is (the target's own faces count as
    facing the right way even where a vertex normal disagrees with them); a partial map's unmatched vertices
    keep their image; a face sent onto one of the target's faces the other way round is turned."""
    wolf0, wolf1 = wolf_pair
    identity = np.arange(wolf0.n_vertices)
    assert not collapsed_or_turned(wolf0.faces, identity, wolf1).any()
    assert np.array_equal(image_on_surface(wolf0, wolf1, identity, wolf1.vertices), wolf1.vertices)
    swapped = identity.copy()
    a, b = wolf0.faces[0, :2]
    swapped[[a, b]] = swapped[[b, a]]
    assert collapsed_or_turned(wolf0.faces, swapped, wolf1)[0]
    partial = np.where(np.arange(wolf0.n_vertices) % 7 == 0, -1, identity)
    partial[wolf0.faces[10]] = wolf0.faces[10, 0]  # one face collapsed to a point
    start = np.where(partial[:, None] >= 0, wolf1.vertices[np.clip(partial, 0, None)], np.nan)
    landed = image_on_surface(wolf0, wolf1, partial, np.where(np.isnan(start), wolf0.vertices, start))
    assert np.array_equal(landed[partial < 0], wolf0.vertices[partial < 0])
    assert triangle_areas(landed, wolf0.faces[10:11])[0] > 0
