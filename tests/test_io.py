"""Loaders and writers: round trips, vertex order, contours from every source, malformed files."""

import json

import numpy as np
import pytest
import trimesh
from PIL import Image

from _data import SILHOUETTES, SKETCH2D, TOSCA
from corrlib.errors import ContourError, FileFormatError, InputError, MeshError, ParameterError
from corrlib.io import (
    atomic_write,
    enclosed_outline,
    load_contour,
    load_labels,
    load_map,
    load_mesh,
    load_result,
    load_vts,
    save_contour,
    save_map,
    save_mesh,
    save_result,
    winding_mask,
)
from corrlib.shapes import Contour2D, inspect_contour


def test_load_keeps_vertex_order():
    mesh = load_mesh(TOSCA / "wolf0.off")
    # first vertex line of the file
    lines = (TOSCA / "wolf0.off").read_text().split("\n")
    header = 1 if lines[0].strip() == "OFF" else 0
    first = np.array([float(x) for x in lines[header + 1].split()])
    assert np.allclose(mesh.vertices[0], first)
    assert mesh.name == "wolf0.off" and mesh.n_vertices == 4344


@pytest.mark.parametrize("suffix", [".off", ".obj", ".ply"])
def test_mesh_round_trip_with_colours(tmp_path, suffix):
    mesh = load_mesh(TOSCA / "wolf0.off")
    colors = np.random.default_rng(0).random((mesh.n_vertices, 3))
    path = save_mesh(tmp_path / f"wolf{suffix}", mesh.vertices, mesh.faces, colors)
    back = load_mesh(path)
    assert np.allclose(back.vertices, mesh.vertices, rtol=1e-8, atol=1e-8)
    assert np.array_equal(back.faces, mesh.faces)
    if suffix == ".ply":
        raw = trimesh.load(path, process=False)
        assert np.array_equal(raw.visual.vertex_colors[:, :3], np.round(colors * 255).astype(np.uint8))


def test_stl_loads(tmp_path):
    box = trimesh.creation.box()
    box.export(tmp_path / "box.stl")
    assert load_mesh(tmp_path / "box.stl").n_faces == 12


@pytest.mark.parametrize("content, match", [
    ("", "empty"),
    ("OFF\n3 1 0\n0 0 0\n1 0 0\n", "announces 3 vertices and 1 faces but the file has only 2"),
    ("this is not a mesh\n", "not an OFF file"),
    ("OFF\n4 0 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n", "no faces"),
    ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1\n", "face 0 announces 3 vertices but lists 2"),
    ("OFF\n3 1 0\n0 0 0\n1 x 0\n0 1 0\n3 0 1 2\n", "vertex line"),
    ("OFF\n3\n", "vertex and face counts"),
    # more faces than the header announces: they would be dropped without a word
    ("OFF\n4 1 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 2 3\n", "1 more data lines after them"),
    # fewer vertices than the file has: the vertex block runs on into the faces
    ("OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 2 3\n", "announces 3 vertices and 2 faces but the "
                                                                 "file has 1 more data lines"),
])
def test_malformed_mesh_files(tmp_path, content, match):
    p = tmp_path / "bad.off"
    p.write_text(content)
    with pytest.raises(FileFormatError, match=match):
        load_mesh(p)
    with pytest.raises(FileFormatError, match="bad.off"):
        load_mesh(p)


def test_mesh_file_errors(tmp_path):
    with pytest.raises(FileFormatError, match="not found"):
        load_mesh(tmp_path / "missing.off")
    (tmp_path / "x.xyz").write_text("1 2 3\n")
    with pytest.raises(FileFormatError, match="unsupported mesh format"):
        load_mesh(tmp_path / "x.xyz")
    p = tmp_path / "nan.off"
    p.write_text("OFF\n3 1 0\n0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n")
    with pytest.raises(MeshError, match="nan.off.*NaN"):
        load_mesh(p)
    p = tmp_path / "range.off"
    p.write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n")
    with pytest.raises((MeshError, FileFormatError), match="range.off"):
        load_mesh(p)


def test_obj_files_that_a_reader_would_misread(tmp_path):
    """An OBJ written with 0-based face indices (a reader takes 0 for the last vertex) and an OBJ of vertices
    alone are named as such."""
    import trimesh

    sphere = trimesh.creation.icosphere(1)
    vertex_lines = [f"v {x} {y} {z}" for x, y, z in sphere.vertices]
    (tmp_path / "zero.obj").write_text("\n".join(vertex_lines + [f"f {a} {b} {c}" for a, b, c in sphere.faces]))
    with pytest.raises(FileFormatError, match="zero.obj: line .* refers to vertex 0, but OBJ vertex indices start"):
        load_mesh(tmp_path / "zero.obj")
    one_based = [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in sphere.faces]
    (tmp_path / "one.obj").write_text("\n".join(vertex_lines + one_based))
    assert load_mesh(tmp_path / "one.obj").n_faces == len(sphere.faces)
    (tmp_path / "points.obj").write_text("\n".join(vertex_lines))
    with pytest.raises(FileFormatError, match="points.obj: the file contains vertices but no faces"):
        load_mesh(tmp_path / "points.obj")


def test_an_ascii_ply_whose_header_miscounts_its_lines_is_refused(tmp_path):
    """A header announcing more vertices than the file has made the reader take face lines for vertices ("43
    vertices belong to no face"); fewer faces dropped the rest."""
    import trimesh

    sphere = trimesh.creation.icosphere(1)
    save_mesh(tmp_path / "s.ply", sphere.vertices, sphere.faces)
    text = (tmp_path / "s.ply").read_text()
    assert load_mesh(tmp_path / "s.ply").n_faces == 80
    for name, announced, match in (("more.ply", ("element vertex 42", "element vertex 100"), "180 in all"),
                                   ("fewer.ply", ("element face 80", "element face 70"), "112 in all")):
        (tmp_path / name).write_text(text.replace(*announced))
        with pytest.raises(FileFormatError, match=f"{name}: the header announces .*\\({match}\\), but the file "
                                                  "has 122 data lines"):
            load_mesh(tmp_path / name)


def test_largest_component_option(tmp_path):
    a = trimesh.creation.icosphere(subdivisions=2)
    b = trimesh.creation.box()
    b.apply_translation([5, 0, 0])
    both = trimesh.util.concatenate([a, b])
    save_mesh(tmp_path / "two.off", both.vertices, both.faces)
    with pytest.raises(MeshError, match="connected components.*keep the largest part, `corr repair"):
        load_mesh(tmp_path / "two.off")
    assert load_mesh(tmp_path / "two.off", largest_component=True).n_vertices == len(a.vertices)


@pytest.mark.parametrize("suffix", [".obj", ".ply"])
def test_a_triangle_soup_is_told_to_weld_its_vertices(tmp_path, suffix):
    """Faces that do not share their corners (every triangle its own three vertices, as STL stores a mesh and
    some exporters write OBJ and PLY) make one component per face; keeping the largest would keep one
    triangle, so the error says to weld instead. An STL file is welded on loading."""
    sphere = trimesh.creation.icosphere(subdivisions=2)
    corners = sphere.vertices[sphere.faces].reshape(-1, 3)
    soup = trimesh.Trimesh(corners, np.arange(len(corners)).reshape(-1, 3), process=False)
    soup.export(tmp_path / f"soup{suffix}")
    repeated = len(corners) - len(sphere.vertices)  # 960 corners at 162 positions
    with pytest.raises(MeshError, match=rf"soup\S*: the mesh has 320 connected components .* {repeated} vertices "
                                        r"repeat the position of another.*1 component would remain.*weld") as caught:
        load_mesh(tmp_path / f"soup{suffix}")
    assert "keep the largest" not in str(caught.value)
    soup.export(tmp_path / "soup.stl")
    assert load_mesh(tmp_path / "soup.stl").n_vertices == len(sphere.vertices)


def test_contour_text_files(tmp_path):
    c = load_contour(SKETCH2D / "human_sketch_a_contour.txt")
    assert c.is_ccw and c.n_points == 427
    t = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    pts = np.column_stack([3 * np.cos(t), np.sin(t)])
    np.savetxt(tmp_path / "e.csv", pts, delimiter=",", header="x,y", comments="")
    e = load_contour(tmp_path / "e.csv", n_points=100)
    assert e.n_points == 100 and e.area == pytest.approx(3 * np.pi, rel=0.01)
    (tmp_path / "bad.txt").write_text("1 2\n3 4 5\n")
    with pytest.raises(FileFormatError, match="bad.txt.*line 2"):
        load_contour(tmp_path / "bad.txt")
    np.savetxt(tmp_path / "arc.txt", pts[:30])
    with pytest.raises(ContourError, match="open contour"):
        load_contour(tmp_path / "arc.txt")
    np.savetxt(tmp_path / "few.txt", pts[::10])
    with pytest.raises(ContourError, match="at least 10"):
        load_contour(tmp_path / "few.txt")
    save_contour(tmp_path / "out.txt", e)
    assert np.allclose(load_contour(tmp_path / "out.txt").points, e.points, atol=1e-8)
    # a byte-order mark (Windows editors write one) is not a header line: every point is kept
    (tmp_path / "bom.txt").write_text("".join(f"{x:.6f} {y:.6f}\n" for x, y in pts), encoding="utf-8-sig")
    assert load_contour(tmp_path / "bom.txt").n_points == 50


def test_svg_path_with_curves(tmp_path):
    # a circle of radius 10 from four cubic Béziers (kappa = 0.5523), relative and absolute commands
    k = 10 * 0.5523
    d = (f"M 10 0 C 10 {k} {k} 10 0 10 c {-k} 0 -10 {-10 + k} -10 -10 "
         f"C -10 {-k} {-k} -10 0 -10 S 10 {-k} 10 0 Z")
    (tmp_path / "c.svg").write_text(f'<svg xmlns="http://www.w3.org/2000/svg"><path d="{d}"/></svg>')
    c = load_contour(tmp_path / "c.svg")
    assert c.area == pytest.approx(np.pi * 100, rel=0.01) and c.is_ccw
    (tmp_path / "p.svg").write_text('<svg><polygon points="0,0 10,0 10,10 0,10 0,5 0,2 1,1 2,0.5 5,0.2 8,0.1"/></svg>')
    assert load_contour(tmp_path / "p.svg").area == pytest.approx(100, rel=0.1)
    (tmp_path / "arc.svg").write_text('<svg><path d="M 0 0 A 5 5 0 0 1 10 0 Z"/></svg>')
    with pytest.raises(FileFormatError, match="arc"):
        load_contour(tmp_path / "arc.svg")
    (tmp_path / "broken.svg").write_text("<svg><path d=")
    with pytest.raises(FileFormatError, match="cannot parse SVG"):
        load_contour(tmp_path / "broken.svg")


@pytest.mark.parametrize("d, message", [("M 0 0 L 1e308 0 L 0 10 Z", "overflow squared lengths"),
                                        ("Q 1e308 0x10 3.", "overflow squared lengths"),
                                        ("M 0 0 L 1e400 0 L 0 1 Z", "NaN or infinite"),
                                        ("M 0 0 T 1e308 0 T 0 1 Z", "NaN or infinite"),  # a reflected control point
                                        ("M 1e308 0 l 1e308 0 l 0 1 Z", "NaN or infinite")])  # a relative step
def test_svg_with_coordinates_too_large_is_refused_by_name(tmp_path, d, message):
    """Found by the fuzzing test: the largest of an SVG's polygons was chosen by an area that overflowed (a
    RuntimeWarning, not a message). The areas are compared at a common scale; the contour is then refused. Path
    arithmetic (relative steps, reflected control points) that overflows gives infinite coordinates, refused too."""
    (tmp_path / "huge.svg").write_text(f'<svg xmlns="http://www.w3.org/2000/svg"><path d="{d}"/></svg>')
    (tmp_path / "two.svg").write_text('<svg><polygon points="0,0 1e-3,0 0,1e-3"/>'
                                      '<polygon points="0,0 1,0 2,0 2,1 2,2 1,2 0,2 0,1.5 0,1 0,0.5"/></svg>')
    with pytest.raises(ContourError, match=message):
        load_contour(tmp_path / "huge.svg")
    assert load_contour(tmp_path / "two.svg").area == pytest.approx(4.0, rel=0.05)  # the larger polygon


@pytest.mark.parametrize("dark_on_light", [True, False])
def test_silhouette_image_disk(tmp_path, dark_on_light):
    yy, xx = np.mgrid[:200, :300]
    disk = (xx - 150) ** 2 + (yy - 100) ** 2 <= 60 ** 2
    img = np.where(disk, 0 if dark_on_light else 255, 255 if dark_on_light else 0).astype(np.uint8)
    Image.fromarray(img).save(tmp_path / "disk.png")
    c = load_contour(tmp_path / "disk.png", n_points=200)
    assert c.n_points == 200 and c.is_ccw
    assert c.area == pytest.approx(np.pi * 60 ** 2, rel=0.02)
    centre = c.points.mean(axis=0)
    assert np.allclose(centre, [150, -100], atol=1.0)  # x right, y up (row 100 -> y = -100)


def test_real_silhouettes():
    for path in sorted((SILHOUETTES / "mpeg7").glob("*.gif")) + [SILHOUETTES / "horse.png"]:
        c = load_contour(path, n_points=300)
        assert c.n_points == 300 and c.is_ccw and c.area > 1000, path
        # the shape, not the picture's frame: horse.png is opaque with a few translucent corner pixels
        with Image.open(path) as im:
            width, height = im.size
        assert c.area < 0.8 * width * height, path


def test_silhouette_from_the_alpha_channel_only_when_the_background_is_transparent(tmp_path):
    yy, xx = np.mgrid[:200, :300]
    disk = (xx - 150) ** 2 + (yy - 100) ** 2 <= 60 ** 2
    rgba = np.zeros((200, 300, 4), np.uint8)
    # an opaque picture (black disk on white) with a few translucent pixels in a corner: read by grey levels
    rgba[..., :3] = np.where(disk, 0, 255)[..., None]
    rgba[..., 3] = 255
    rgba[:3, :3, 3] = 110
    Image.fromarray(rgba, "RGBA").save(tmp_path / "opaque.png")
    assert load_contour(tmp_path / "opaque.png").area == pytest.approx(np.pi * 60 ** 2, rel=0.02)
    # a white disk on a transparent background: the alpha channel is the silhouette
    rgba[..., :3] = 255
    rgba[..., 3] = np.where(disk, 255, 0)
    Image.fromarray(rgba, "RGBA").save(tmp_path / "transparent.png")
    assert load_contour(tmp_path / "transparent.png").area == pytest.approx(np.pi * 60 ** 2, rel=0.02)


def test_bad_images(tmp_path):
    (tmp_path / "junk.png").write_bytes(b"not an image at all")
    with pytest.raises(FileFormatError, match="cannot read image"):
        load_contour(tmp_path / "junk.png")
    Image.fromarray(np.full((50, 50), 128, np.uint8)).save(tmp_path / "flat.png")
    with pytest.raises(ContourError, match="uniform"):
        load_contour(tmp_path / "flat.png")
    tiny = np.zeros((50, 50), np.uint8)
    tiny[20, 20] = 255
    Image.fromarray(tiny).save(tmp_path / "tiny.png")
    with pytest.raises(ContourError, match="too small|at least 10"):
        load_contour(tmp_path / "tiny.png")


def test_vts_and_maps(tmp_path):
    gt = load_vts(TOSCA / "cat0.vts", 5000)
    assert gt.min() >= 0 and gt.max() < 5000 and gt.size == 5000
    (tmp_path / "zero.vts").write_text("0\n1\n2\n")
    with pytest.raises(FileFormatError, match="1-based"):
        load_vts(tmp_path / "zero.vts")
    (tmp_path / "big.vts").write_text("1\n9\n")
    with pytest.raises(FileFormatError, match="exceeds"):
        load_vts(tmp_path / "big.vts", 5)
    save_map(tmp_path / "m.txt", np.array([3, 1, 2]))
    assert np.array_equal(load_map(tmp_path / "m.txt"), [3, 1, 2])
    with pytest.raises(FileFormatError, match="out of range"):
        load_map(tmp_path / "m.txt", n_target=3)
    with pytest.raises(FileFormatError, match="source has 4"):
        load_map(tmp_path / "m.txt", n_source=4)
    (tmp_path / "f.txt").write_text("1.5\n2\n")
    with pytest.raises(FileFormatError, match="integer"):
        load_map(tmp_path / "f.txt")
    # two columns (a landmarks file given as a map) were read as one list of twice the rows
    np.savetxt(tmp_path / "pairs.txt", np.column_stack([np.arange(3), np.arange(3)]), fmt="%d")
    with pytest.raises(FileFormatError, match="pairs.txt: the map file must hold one integer per line; data line 1 "
                                              "has 2 values"):
        load_map(tmp_path / "pairs.txt")
    with pytest.raises(FileFormatError, match="one integer per line"):
        load_vts(tmp_path / "pairs.txt")
    (tmp_path / "labels.txt").write_text("4611686018427387904\n")
    with pytest.raises(FileFormatError, match="must hold integer labels; entry 0 is .* \\(beyond 2\\^53"):
        load_labels(tmp_path / "labels.txt")
    with pytest.raises(InputError, match="integer array"):
        save_map(tmp_path / "x.txt", np.array([0.5]))


def test_results_round_trip_without_pickle(tmp_path):
    npz, js = save_result(tmp_path / "r", {"map_xy": np.arange(5), "energy_trace": np.ones(3)},
                          {"method": "x", "params": {"k": 3}, "timings": {"total": np.float64(1.5)}})
    arrays, meta = load_result(tmp_path / "r")
    assert np.array_equal(arrays["map_xy"], np.arange(5))
    assert meta["method"] == "x" and meta["timings"]["total"] == 1.5 and "numpy" in meta["environment"]
    assert json.loads(js.read_text())["arrays"]["map_xy"]["shape"] == [5]
    with pytest.raises(InputError, match="not numeric"):
        save_result(tmp_path / "o", {"bad": np.array([object()])})


def test_atomic_write_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "keep.txt"
    target.write_text("precious")
    with pytest.raises(RuntimeError):
        with atomic_write(target) as fh:
            fh.write("half")
            raise RuntimeError("crash mid-write")
    assert target.read_text() == "precious"
    assert list(tmp_path.iterdir()) == [target]


def test_atomic_write_uses_normal_permissions(tmp_path):
    import os
    import stat

    old = os.umask(0o022)
    try:
        save_map(tmp_path / "m.txt", np.arange(3))
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "m.txt").stat().st_mode) == 0o644


def _winding_numbers(polygon: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Winding number of a closed polygon round every point, as the sum of the signed angles its edges
    subtend (an independent definition of what the scanlines of ``winding_mask`` count)."""
    a = polygon[None, :, :] - points[:, None, :]
    b = np.roll(polygon, -1, axis=0)[None, :, :] - points[:, None, :]
    angles = np.arctan2(a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0], np.sum(a * b, axis=-1))
    return np.rint(angles.sum(axis=1) / (2 * np.pi)).astype(int)


def test_winding_mask_is_the_winding_number_rule():
    angles = 4 * np.pi * np.arange(5) / 5  # a pentagram winds twice round its centre
    pentagram = 15 + 11 * np.column_stack([np.cos(angles), np.sin(angles)])
    rng = np.random.default_rng(3)
    rows, cols = np.mgrid[0:30, 0:30]
    centres = np.column_stack([cols.ravel() + 0.5, rows.ravel() + 0.5])
    for polygon in [pentagram] + [rng.uniform(1.0, 29.0, size=(12, 2)) for _ in range(3)]:
        winding = _winding_numbers(polygon, centres).reshape(30, 30)
        np.testing.assert_array_equal(winding_mask(polygon, 30, 30), winding != 0)
    assert _winding_numbers(pentagram, np.array([[15.0, 15.0]]))[0] == 2  # inside, though wound round twice


def _traced(corners: np.ndarray, n: int) -> np.ndarray:
    closed = np.vstack([corners, corners[:1]])
    length = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))]
    s = np.linspace(0.0, length[-1], n, endpoint=False)
    return np.column_stack([np.interp(s, length, closed[:, 0]), np.interp(s, length, closed[:, 1])])


def test_enclosed_outline_of_a_stroke_that_overshoots_its_start():
    square = _traced(np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]), 200)
    stroke = np.vstack([square, [[0.0, -0.3], [0.5, -0.3], [1.5, 0.2]]])  # past the start, across the first edge
    assert [f.code for f in inspect_contour(stroke)] == ["self-intersection"]
    outline = enclosed_outline(stroke)
    assert not inspect_contour(outline)  # a simple polygon
    cell = 10.3 / 1020
    assert Contour2D(outline).area == pytest.approx(100.0 + 0.5 * 1.5 * 0.3, abs=40 * cell)
    # every outline point lies on the square's sides or on the overshoot, within a cell
    off_square = np.minimum.reduce([np.abs(outline[:, 0]), np.abs(outline[:, 0] - 10), np.abs(outline[:, 1]),
                                    np.abs(outline[:, 1] - 10)])
    assert np.all((off_square <= cell) | (outline[:, 1] < 0.2 + cell))
    # an outline of a simple polygon is the polygon, scaled and moved with it
    far = enclosed_outline(square * 1e3 + 5e4)
    assert Contour2D(far).area == pytest.approx(1e8, rel=1e-2)
    assert np.allclose(far.min(axis=0), 5e4, atol=12.0) and np.allclose(far.max(axis=0), 6e4, atol=12.0)


def test_enclosed_outline_of_a_figure_eight_holds_both_loops():
    t = np.linspace(0.0, 2 * np.pi, 200, endpoint=False)
    big = np.column_stack([3 + 3 * np.cos(t + np.pi), 3 * np.sin(t + np.pi)])  # through the origin, anticlockwise
    small = np.column_stack([-1 + np.cos(t), -np.sin(t)])  # through the origin the other way round
    outline = enclosed_outline(np.vstack([big, small]))
    assert not inspect_contour(outline)
    assert Contour2D(outline).area == pytest.approx(10 * np.pi, rel=1e-2)  # each loop is wound round once


def test_enclosed_outline_of_a_drawing_without_area():
    line = np.column_stack([np.r_[np.linspace(0, 5, 20), np.linspace(5, 0, 20)], np.zeros(40)])
    with pytest.raises(ContourError, match="sketch: the contour encloses no area"):
        enclosed_outline(line, name="sketch")
    with pytest.raises(ContourError, match="sketch: the contour has 1 distinct points"):
        enclosed_outline(np.ones((5, 2)), name="sketch")
    with pytest.raises(ContourError, match="sketch: 1 contour points are NaN"):
        enclosed_outline(np.array([[0.0, 0.0], [1.0, np.nan], [2.0, 0.0]]), name="sketch")
    with pytest.raises(ContourError, match="sketch: the drawing encloses no area"):  # a sliver below a cell
        enclosed_outline(np.array([[0.0, 0.0], [1000.0, 0.0], [1000.0, 1e-4], [0.0, 1e-4]]), name="sketch")
    with pytest.raises(ContourError, match="sketch: coordinates up to .* overflow"):
        enclosed_outline(np.array([[0.0, 0.0], [1e308, 0.0], [1e308, 1e308], [5e307, -1e308]]), name="sketch")
    with pytest.raises(ParameterError, match="resolution must be a whole number of at least 16"):
        enclosed_outline(line, resolution=8)
    with pytest.raises(ContourError, match="sketch: contour points are complex"):
        enclosed_outline(np.array([[0, 0], [1, 0], [1j, 1]]), name="sketch")


def test_a_map_s_record_is_read_only_where_it_is_a_result_s(tmp_path):
    """``check_map_record`` reads the ``.json`` that ``corr match`` writes beside its maps: a record of other
    meshes is named; a record that cannot be read, holds no inputs or an edited shape print, or a map file of
    another name, leaves the map to the size checks (these files are not the user's to keep valid)."""
    from corrlib.io import check_map_record, load_mesh
    from corrlib.methods import solve

    wolf0, wolf1 = load_mesh(TOSCA / "wolf0.off"), load_mesh(TOSCA / "wolf1.off")
    solve("descriptor-nn", wolf0, wolf1).save(tmp_path / "r")
    check_map_record(tmp_path / "r.npz", wolf0, wolf1)
    with pytest.raises(FileFormatError, match=r"r.npz: the map was computed for the target 'wolf1.off' \(4344 "
                                              r"vertices, says r.json\), not for 'wolf0.off'"):
        check_map_record(tmp_path / "r.npz", target=wolf0)
    record = json.loads((tmp_path / "r.json").read_text())
    record["inputs"]["target"]["shape_print"] = "edited"
    (tmp_path / "r.json").write_text(json.dumps(record))
    check_map_record(tmp_path / "r.map_xy.txt", target=wolf0)
    for text in ("{not json", "[1, 2]", '{"method": "m"}'):
        (tmp_path / "r.json").write_text(text)
        check_map_record(tmp_path / "r.npz", wolf1, wolf0)
    check_map_record(tmp_path / "other.txt", wolf1, wolf0)
