"""Filling a contour: boundary first and in order, area, quality, orientation."""

import numpy as np
import pytest

from _data import SILHOUETTES, SKETCH2D
from corrlib.errors import ParameterError
from corrlib.geometry.triangulate import fill_contour
from corrlib.io import load_contour
from corrlib.shapes import Contour2D


def min_angles(mesh):
    v = mesh.vertices[mesh.faces]
    out = []
    for k in range(3):
        a = v[:, (k + 1) % 3] - v[:, k]
        b = v[:, (k + 2) % 3] - v[:, k]
        cos = np.einsum("ij,ij->i", a, b) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)
        out.append(np.degrees(np.arccos(np.clip(cos, -1, 1))))
    return np.min(out, axis=0)


@pytest.mark.parametrize("path", [SKETCH2D / "human_sketch_a_contour.txt", SILHOUETTES / "mpeg7" / "dog-1.gif"])
def test_fill_real_contours(path):
    contour = load_contour(path, n_points=300) if path.suffix == ".gif" else load_contour(path)
    mesh = fill_contour(contour)
    m = contour.n_points
    assert np.array_equal(mesh.vertices[:m, :2], contour.points)
    assert np.all(mesh.vertices[:, 2] == 0)
    assert mesh.area == pytest.approx(contour.area, rel=1e-9)
    # the boundary of the filled mesh is exactly the contour, in order
    loops = mesh.boundary_loops
    assert len(loops) == 1 and sorted(loops[0]) == list(range(m))
    directed = {tuple(e) for e in mesh.boundary_edges}
    assert all((i, (i + 1) % m) in directed for i in range(m))  # ccw contour = ccw faces
    assert np.all(mesh.face_normals[:, 2] > 0)
    # Triangle guarantees the angle bound except at sharp input corners (Y switch: no boundary splits)
    assert np.mean(min_angles(mesh) >= 29.9) > 0.95
    assert mesh.n_vertices > m  # interior vertices were added


def test_fill_clockwise_and_density():
    t = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    cw = Contour2D(np.column_stack([np.cos(t), -np.sin(t)]))
    coarse = fill_contour(cw)
    fine = fill_contour(cw, density=2.0)
    assert np.all(coarse.face_normals[:, 2] > 0)
    assert fine.n_vertices > 2.5 * (coarse.n_vertices - 60) + 60
    with pytest.raises(ParameterError, match="min_angle"):
        fill_contour(cw, min_angle=40)
    with pytest.raises(ParameterError, match="density"):
        fill_contour(cw, density=0)
