"""TriMesh / Contour2D: derived quantities and every validation error."""

import numpy as np
import pytest
import trimesh

from corrlib.errors import ContourError, MeshError
from corrlib.shapes import Contour2D, TriMesh, inspect_contour, inspect_mesh

TETRA_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
TETRA_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def codes(v, f):
    return [fd.code for fd in inspect_mesh(v, f) if fd.level == "error"]


def test_tetrahedron_quantities():
    m = TriMesh(TETRA_V, TETRA_F, name="tet")
    assert m.n_vertices == 4 and m.n_faces == 4
    assert m.area == pytest.approx(1.5 + np.sqrt(3) / 2)
    assert m.is_closed and m.boundary_loops == ()
    assert m.enclosed_volume() == pytest.approx(1 / 6)
    assert m.edges.shape == (6, 2)
    assert np.allclose(np.linalg.norm(m.vertex_normals, axis=1), 1)
    # outward normals: the face opposite the origin points along (1,1,1)
    assert np.allclose(m.face_normals[3], np.ones(3) / np.sqrt(3))
    with pytest.raises(ValueError):
        m.vertices[0, 0] = 5.0  # immutable


def test_cube_volume_and_boundary():
    box = trimesh.creation.box(extents=(1, 2, 3))
    m = TriMesh(box.vertices, box.faces)
    assert m.enclosed_volume() == pytest.approx(6.0)
    open_box = TriMesh(box.vertices, box.faces[2:])
    assert not open_box.is_closed and open_box.enclosed_volume() is None
    assert len(open_box.boundary_loops) == 1 and len(open_box.boundary_loops[0]) == 4
    assert any(fd.code == "boundary" for fd in open_box.report())


@pytest.mark.parametrize("vertices, faces, code, match", [
    (np.zeros((0, 3)), np.zeros((0, 3), int), "empty", "no vertices"),
    (TETRA_V, np.zeros((0, 3), int), "empty", "no faces"),
    (TETRA_V[:, :2], TETRA_F, "vertices-shape", r"shape \(n, 3\)"),
    (TETRA_V, np.array([[0, 1, 2, 3]]), "faces-shape", "triangles only"),
    (np.where(np.arange(12).reshape(4, 3) == 4, np.nan, TETRA_V), TETRA_F, "non-finite", "NaN"),
    (TETRA_V, np.vstack([TETRA_F, [[0, 1, 7]]]), "index-range", "outside"),
    (TETRA_V, np.vstack([TETRA_F[:3], [[1, 1, 3]]]), "degenerate-face", "repeat a vertex"),
    (np.vstack([TETRA_V, [[1, 1, -1]]]), np.vstack([TETRA_F, [[1, 2, 4]]]), "non-manifold-edge",
     "more than two faces"),
    (np.vstack([TETRA_V, [[5, 5, 5]]]), TETRA_F, "unreferenced-vertex", "belong to no face"),
    (TETRA_V, np.array([[0, 2, 1.5]]), "faces-type", "not integers"),
])
def test_mesh_validation_errors(vertices, faces, code, match):
    assert code in codes(vertices, faces)
    with pytest.raises(MeshError, match=match):
        TriMesh(vertices, faces, name="bad.off")
    with pytest.raises(MeshError, match="bad.off"):
        TriMesh(vertices, faces, name="bad.off")


def test_zero_area_face():
    v = np.vstack([TETRA_V, [[0.5, 0.5, 0.0]]])  # on the segment 1-2: collinear with them
    f = np.vstack([TETRA_F, [[1, 4, 2]]])
    assert "zero-area-face" in codes(v, f)
    with pytest.raises(MeshError, match="zero area"):
        TriMesh(v, f)


def test_a_small_face_is_not_a_degenerate_one():
    """A well-shaped face 1e-8 of the shape's size (marching cubes leaves such faces where the surface passes near
    a grid point) has well-defined angles: the mesh is valid. A long face whose apex lies 1e-13 of the shape's size
    off its base is flat to the coordinates' precision: refused, although its area is 25 times the smallest one's."""
    from corrlib.shapes import degenerate_faces

    # a unit right triangle cut at its corner: a tiny right triangle (a, p, q) and two large faces
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1e-8, 0, 0], [0, 1e-8, 0]], dtype=float)
    f = np.array([[0, 3, 4], [3, 1, 2], [3, 2, 4]])
    assert not degenerate_faces(v, f).any()
    assert "zero-area-face" not in codes(v, f)
    assert TriMesh(v, f).face_areas[0] == pytest.approx(5e-17)
    flat = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1e-13, 0], [0.5, 1, 0]], dtype=float)
    assert degenerate_faces(flat, np.array([[0, 1, 2], [0, 2, 3]])).tolist() == [True, False]
    with pytest.raises(MeshError, match="collinear or coincide"):
        TriMesh(flat, np.array([[0, 1, 2], [2, 1, 3], [0, 2, 3]]))


def test_a_pinched_vertex_is_named():
    """Two tetrahedra sharing one vertex (and a sphere through the same test) are one connected mesh whose every
    edge borders two faces, so nothing was said; the vertex where they touch joins two fans of faces."""
    import trimesh

    warnings = lambda v, f: [fd for fd in inspect_mesh(v, f) if fd.code == "pinched-vertex"]  # noqa: E731
    v = np.vstack([TETRA_V, TETRA_V[1:] - 2.0])  # the second one's apex is vertex 0 as well
    f = np.vstack([TETRA_F, np.where(TETRA_F == 0, 0, TETRA_F + 3)])
    found = warnings(v, f)
    assert len(found) == 1 and found[0].level == "warning" and "1 vertices" in found[0].message
    assert "vertex 0" in found[0].message
    sphere = trimesh.creation.icosphere(2)
    assert not warnings(sphere.vertices, sphere.faces) and not warnings(TETRA_V, TETRA_F)
    cap = sphere.faces[sphere.vertices[sphere.faces].mean(axis=1)[:, 2] > 0.3]  # an open surface: one fan each
    assert not warnings(sphere.vertices, cap)


def test_components_error_and_largest_component():
    a = trimesh.creation.icosphere(subdivisions=2)
    v = np.vstack([TETRA_V + 10, a.vertices])
    f = np.vstack([TETRA_F, a.faces + 4])
    with pytest.raises(MeshError, match="2 connected components"):
        TriMesh(v, f)
    m = TriMesh.from_arrays(v, f, largest_component=True)
    assert m.n_vertices == len(a.vertices)
    assert np.array_equal(m.original_indices, np.arange(4, 4 + len(a.vertices)))
    assert np.allclose(m.vertices, a.vertices)


def test_orientation_warning():
    f = TETRA_F.copy()
    f[0] = f[0][::-1]
    assert any(fd.code == "orientation" for fd in inspect_mesh(TETRA_V, f))


def warnings_of(v, f):
    return [fd.code for fd in inspect_mesh(v, f) if fd.level == "warning"]


def _mobius_strip(n=20):
    """A triangulated Möbius strip: one-sided, so no winding of its faces agrees across every edge."""
    angles = np.linspace(0, 2 * np.pi, n, endpoint=False)
    v = np.array([[(2 + 0.5 * w * np.cos(t / 2)) * np.cos(t), (2 + 0.5 * w * np.cos(t / 2)) * np.sin(t),
                   0.5 * w * np.sin(t / 2)] for t in angles for w in (-1, 1)])
    f = []
    for i in range(n):
        a, b = 2 * i, 2 * i + 1
        c, d = (2 * i + 2, 2 * i + 3) if i < n - 1 else (1, 0)  # the last quad closes with the half twist
        f += [[a, c, b], [b, c, d]]
    return v, np.array(f)


@pytest.mark.parametrize("every", [2, 3, 7])
def test_inconsistent_windings_are_turned_to_agree(every):
    """Every ``every``-th face of a sphere turned (an exporter's mistake): the faces are turned back to agree
    with their neighbours, keeping the winding most faces had; a consistent mesh and a one-sided surface are
    left as they are."""
    from corrlib.shapes import consistently_oriented

    sphere = trimesh.creation.icosphere(3)
    v, f = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    mixed = f.copy()
    mixed[::every] = mixed[::every, ::-1]
    fixed, turned = consistently_oriented(mixed, len(v))
    assert turned == min(len(f[::every]), len(f) - len(f[::every]))
    assert "orientation" in warnings_of(v, mixed) and "orientation" not in warnings_of(v, fixed)
    volume, outside = TriMesh(v, fixed).enclosed_volume(), TriMesh(v, f).enclosed_volume()
    assert abs(volume) == pytest.approx(outside)  # one winding everywhere: all out or all in
    if every > 2:  # the majority's winding, the outside: the file's faces exactly
        assert np.array_equal(fixed, f)
    same, zero = consistently_oriented(f, len(v))
    assert zero == 0 and np.array_equal(same, f)
    strip_v, strip_f = _mobius_strip()
    assert "orientation" in warnings_of(strip_v, strip_f)
    unchanged, none = consistently_oriented(strip_f, len(strip_v))
    assert none == 0 and np.array_equal(unchanged, strip_f)


def test_a_loaded_mesh_with_turned_faces_is_reoriented_and_says_so(tmp_path):
    from corrlib.io import load_mesh, save_mesh

    sphere = trimesh.creation.icosphere(3)
    f = np.asarray(sphere.faces).copy()
    f[::3] = f[::3, ::-1]
    save_mesh(tmp_path / "mixed.off", sphere.vertices, f)
    mesh = load_mesh(tmp_path / "mixed.off")
    assert np.array_equal(mesh.faces, sphere.faces)
    notes = [fd.message for fd in mesh.report() if fd.code == "reoriented"]
    assert notes == [f"{len(f[::3])} faces were turned to agree with their neighbours (the file's face "
                     "orientation was inconsistent)"]


def test_a_closed_mesh_wound_inwards_is_turned_out_and_says_so(tmp_path):
    """A closed surface whose faces all wind inwards (negative enclosed volume: an inside-out export, or a mirror
    image whose faces were not rewound) is turned so that its normals point out, with a note; so is one whose
    majority winding is inward (first made consistent, then turned); an open surface has no inside and is
    kept as it is. The synthetic people were generated inside out until this check showed it."""
    from corrlib.io import load_mesh, save_mesh

    sphere = trimesh.creation.icosphere(3)
    outward = np.asarray(sphere.faces)
    save_mesh(tmp_path / "inside_out.off", sphere.vertices, outward[:, ::-1])
    save_mesh(tmp_path / "mirrored.off", sphere.vertices * [-1.0, 1.0, 1.0], outward)
    mostly_inward = outward[:, ::-1].copy()
    mostly_inward[::5] = outward[::5]
    save_mesh(tmp_path / "mostly_inward.off", sphere.vertices, mostly_inward)
    for name in ("inside_out", "mirrored", "mostly_inward"):
        mesh = load_mesh(tmp_path / f"{name}.off")
        assert mesh.enclosed_volume() > 0 and "inside-out" in [fd.code for fd in mesh.report()], name
    assert np.array_equal(load_mesh(tmp_path / "inside_out.off").faces, outward[:, ::-1][:, ::-1])
    assert "reoriented" in [fd.code for fd in load_mesh(tmp_path / "mostly_inward.off").report()]
    save_mesh(tmp_path / "outward.off", sphere.vertices, outward)
    assert not {"inside-out", "reoriented"} & {fd.code for fd in load_mesh(tmp_path / "outward.off").report()}
    cap = outward[sphere.vertices[outward].mean(axis=1)[:, 2] > 0]  # the upper half: open
    used, cap = np.unique(cap, return_inverse=True)
    save_mesh(tmp_path / "cap.off", sphere.vertices[used], cap.reshape(-1, 3)[:, ::-1])
    cap_mesh = load_mesh(tmp_path / "cap.off")
    assert cap_mesh.enclosed_volume() is None and "inside-out" not in [fd.code for fd in cap_mesh.report()]
    # a closed surface that encloses nothing: a square's two sides, the back a fan round a centre 1e-12 off the
    # plane on the wrong side, so its volume is -3e-13, rounding next to its area: nothing is turned
    pillow_points = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1e-12]])
    pillow_faces = np.array([[0, 1, 2], [0, 2, 3], [4, 1, 0], [4, 2, 1], [4, 3, 2], [4, 0, 3]])
    save_mesh(tmp_path / "pillow.off", pillow_points, pillow_faces)
    pillow = load_mesh(tmp_path / "pillow.off")
    assert pillow.enclosed_volume() < 0 and np.array_equal(pillow.faces, pillow_faces)
    assert "inside-out" not in [fd.code for fd in pillow.report()]


def square(n=40, side=2.0):
    t = np.linspace(0, 4, n, endpoint=False)
    pts = []
    for s in t:
        k, r = int(s), s - int(s)
        corners = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]], float)
        pts.append(corners[k] + r * (corners[k + 1] - corners[k]))
    return side * np.array(pts)


def test_contour_quantities_and_resampling():
    c = Contour2D(square())
    assert c.is_ccw and c.area == pytest.approx(4.0) and c.length == pytest.approx(8.0)
    cw = Contour2D(square()[::-1])
    assert not cw.is_ccw and cw.ccw().is_ccw
    assert np.array_equal(cw.ccw().points[0], cw.points[0])
    r = c.resample(16)  # 16 points on a square of perimeter 8: the corners are kept exactly
    assert r.n_points == 16
    assert np.allclose(r.segment_lengths, 0.5) and r.length == pytest.approx(8.0)
    t = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    circle = Contour2D(np.column_stack([np.cos(t), np.sin(t)])).resample(13)
    assert np.allclose(circle.segment_lengths, circle.segment_lengths.mean(), rtol=1e-3)
    assert np.allclose(circle.points[0], [1, 0])
    t = c.transformed(scale=3.0, rotation=0.7, translation=(1, 2))
    assert t.area == pytest.approx(36.0) and t.length == pytest.approx(24.0)
    # a repeated closing point and consecutive duplicates are dropped
    pts = np.vstack([square(), square()[:1]])
    pts = np.insert(pts, 5, pts[5], axis=0)
    assert Contour2D(pts).n_points == 40


@pytest.mark.parametrize("points, match", [
    (np.zeros((0, 2)), "no points"),
    (np.zeros((12, 3)), r"shape \(m, 2\)"),
    (np.where(np.arange(80).reshape(40, 2) == 7, np.inf, square()), "NaN or infinite"),
    (square(8), "at least 10"),
    (np.column_stack([np.linspace(0, 1, 20), np.linspace(0, 1, 20)]), "encloses no area"),
])
def test_contour_validation_errors(points, match):
    with pytest.raises(ContourError, match=match):
        Contour2D(points, name="sketch")


def test_self_intersecting_contour():
    t = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    figure_eight = np.column_stack([np.sin(t), np.sin(t) * np.cos(t)])
    assert any(fd.code == "self-intersection" for fd in inspect_contour(figure_eight))
    with pytest.raises(ContourError, match="intersects itself"):
        Contour2D(figure_eight)
    # a bow-tie with a crossing between far-apart segments
    p = square()
    p[[5, 25]] = p[[25, 5]]
    with pytest.raises(ContourError, match="intersects itself"):
        Contour2D(p)


def test_self_intersection_matches_brute_force():
    rng = np.random.default_rng(1)
    for _ in range(30):
        p = rng.normal(size=(12, 2))
        from corrlib.shapes import _segments_intersect

        fast = {tuple(x) for x in _segments_intersect(p)}
        brute = set()
        m = len(p)
        for i in range(m):
            for j in range(i + 1, m):
                if j == i + 1 or (i == 0 and j == m - 1):
                    continue
                a, b, c, d = p[i], p[(i + 1) % m], p[j], p[(j + 1) % m]
                o = lambda p1, p2, q: np.sign((p2[0] - p1[0]) * (q[1] - p1[1]) - (p2[1] - p1[1]) * (q[0] - p1[0]))  # noqa: E731
                if o(a, b, c) * o(a, b, d) <= 0 and o(c, d, a) * o(c, d, b) <= 0:
                    brute.add((i, j))
        assert fast == brute


def test_open_contour_detection():
    t = np.linspace(0, 1.5 * np.pi, 50)
    arc = np.column_stack([np.cos(t), np.sin(t)])
    with pytest.raises(ContourError, match="open contour"):
        Contour2D.from_open_points(arc)
    assert Contour2D.from_open_points(arc, assume_closed=True).n_points == 50
    t = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    circle = np.column_stack([np.cos(t), np.sin(t)])
    assert Contour2D.from_open_points(circle).n_points == 50


@pytest.mark.parametrize("scale, accepted", [(1e100, False), (1e70, True), (1e-70, True), (1e-100, False)])
def test_mesh_coordinates_are_usable_only_where_squared_areas_are(scale, accepted):
    """A mesh forms squared triangle areas (fourth powers of its coordinates): at 1e140 its area was already
    infinite after validation passed, and a method then failed with a misleading message."""
    v = TETRA_V * scale
    if accepted:
        mesh = TriMesh(v, TETRA_F)
        assert np.isfinite(mesh.area) and mesh.area > 0
    else:
        with pytest.raises(MeshError, match="squared triangle areas"):
            TriMesh(v, TETRA_F)


def test_complex_coordinates_and_indices_beyond_int64_are_refused_by_name():
    """NumPy drops imaginary parts with only a warning, and a face index of 2**70 raised OverflowError."""
    faces = TETRA_F.tolist()
    with pytest.raises(MeshError, match="complex numbers"):
        TriMesh(TETRA_V + 1j, TETRA_F)
    with pytest.raises(MeshError, match="faces are not integer vertex indices"):
        TriMesh(TETRA_V, faces[:-1] + [[0, 1, 2 ** 70]])
    with pytest.raises(ContourError, match="complex numbers"):
        Contour2D(square() + 1j)


# ----------------------------------------------------------------------------- planar sketch meshes


def _sketch():
    from _data import SKETCH2D
    from corrlib.io import load_mesh

    return load_mesh(SKETCH2D / "human_sketch_a.off")


def test_plane_coordinates_keep_a_coordinate_plane_and_are_isometric_in_any_plane():
    from scipy.spatial.transform import Rotation

    from corrlib.shapes import plane_coordinates

    rng = np.random.default_rng(0)
    flat = rng.standard_normal((50, 2))
    for axis in range(3):  # normal to x, y or z: the other two axes, in order
        points = np.insert(flat, axis, 7.0, axis=1)
        assert np.array_equal(plane_coordinates(points), flat)
    turned = np.insert(flat, 2, 0.0, axis=1) @ Rotation.from_euler("xyz", [0.4, -0.7, 1.1]).as_matrix().T + 3.0
    mapped = plane_coordinates(turned)
    pairwise = lambda p: np.linalg.norm(p[:, None] - p[None], axis=-1)  # noqa: E731
    assert mapped.shape == (50, 2) and np.allclose(pairwise(mapped), pairwise(flat))
    bumped = turned.copy()
    bumped[7] += 1e-3 * Rotation.from_euler("xyz", [0.4, -0.7, 1.1]).as_matrix()[:, 2]  # off the plane
    assert plane_coordinates(bumped) is None
    assert plane_coordinates(rng.standard_normal((20, 3))) is None


def test_a_sketch_mesh_outline_is_its_boundary_in_its_plane_wherever_the_plane_is():
    from scipy.spatial.transform import Rotation

    from corrlib.shapes import sketch_outline

    sketch = _sketch()
    outline, loop = sketch_outline(sketch)
    assert loop.size == max(len(b) for b in sketch.boundary_loops) and outline.name == sketch.name
    assert np.array_equal(outline.points, sketch.vertices[loop, :2])  # drawn in the xy plane: kept as drawn
    rotation = Rotation.from_euler("xyz", [1.0, 0.3, -0.5]).as_matrix()
    turned, turned_loop = sketch_outline(TriMesh(sketch.vertices @ rotation.T, sketch.faces, name="turned"))
    assert np.array_equal(turned_loop, loop)
    assert np.allclose(turned.segment_lengths, outline.segment_lengths)  # the same outline, moved in its plane
    assert abs(turned.area - outline.area) < 1e-9 * outline.area


def test_a_mesh_that_is_not_flat_or_has_no_boundary_is_no_sketch(wolf_pair):
    from corrlib.shapes import sketch_outline

    with pytest.raises(MeshError, match="wolf0.off: not a planar sketch: its vertices do not lie in a plane"):
        sketch_outline(wolf_pair[0])
    square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
    two_sided = TriMesh(square, [[0, 1, 2], [0, 2, 3], [0, 2, 1], [0, 3, 2]], name="two-sided", validate=False)
    with pytest.raises(MeshError, match="two-sided: the sketch mesh has no boundary"):
        sketch_outline(two_sided)
