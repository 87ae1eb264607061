"""Decimation to a vertex budget (corrlib.geometry.decimation)."""

import numpy as np
import pytest
import trimesh

from corrlib.geometry.decimation import decimated
from corrlib.shapes import TriMesh


@pytest.fixture(scope="module")
def sphere():
    ico = trimesh.creation.icosphere(subdivisions=5, radius=2.0)  # 10,242 vertices
    return TriMesh(ico.vertices, ico.faces, name="sphere")


def test_a_mesh_within_the_budget_is_not_decimated(sphere):
    assert decimated(sphere, sphere.n_vertices) is None
    assert decimated(sphere, 10 * sphere.n_vertices) is None


def test_the_decimated_sphere_keeps_its_surface_and_topology(sphere):
    coarse = decimated(sphere, 2000)
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
    coarse = decimated(sphere, 1000)
    distances = np.linalg.norm(coarse.mesh.vertices[:, None, :] - sphere.vertices[None, :, :], axis=2)
    chosen = np.linalg.norm(coarse.mesh.vertices - sphere.vertices[coarse.to_original], axis=1)
    assert np.allclose(chosen, distances.min(axis=1), rtol=0, atol=1e-12)  # the nearest, up to ties
    spacing = np.mean(np.linalg.norm(np.diff(sphere.vertices[sphere.faces[:, :2]], axis=1)[:, 0], axis=1))
    assert np.max(np.linalg.norm(coarse.mesh.vertices - sphere.vertices[coarse.to_original], axis=1)) < spacing


def test_part_labels_follow_the_nearest_input_vertex(sphere):
    labels = np.where(sphere.vertices[:, 0] > 0, 1, 2)
    coarse = decimated(sphere.with_labels(labels), 1500)
    assert np.array_equal(coarse.mesh.labels, labels[coarse.to_original])
    away_from_the_border = np.abs(coarse.mesh.vertices[:, 0]) > 0.1
    expected = np.where(coarse.mesh.vertices[:, 0] > 0, 1, 2)
    assert np.array_equal(coarse.mesh.labels[away_from_the_border], expected[away_from_the_border])
