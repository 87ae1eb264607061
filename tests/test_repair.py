"""`corr repair` and corrlib.repair: each repair on a mesh that needs it, the index back to the input, and what
has no repair refused by name."""

import numpy as np
import pytest
import trimesh

from _data import TOSCA
from corrlib.cli import main
from corrlib.errors import MeshError
from corrlib.io import load_mesh, read_mesh_arrays, save_mesh
from corrlib.repair import repaired
from corrlib.shapes import inspect_mesh


def _errors(v, f):
    return [fd.code for fd in inspect_mesh(v, f) if fd.level == "error"]


def _damaged_wolf():
    """wolf0 with a far tetrahedron, a loose vertex, a repeated face, a flat face on a new vertex at an edge's
    midpoint, and one vertex's position repeated by a copy that two of its faces use (a split seam)."""
    wolf = load_mesh(TOSCA / "wolf0.off")
    v, f = wolf.vertices.copy(), wolf.faces.copy()
    n = len(v)
    tetrahedron = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float) * 5 + v.max(axis=0) + 50
    a, b = f[0, 0], f[0, 1]
    v = np.vstack([v, tetrahedron, [[1e3, 1e3, 1e3]], [(v[a] + v[b]) / 2], v[7:8]])
    seam = np.flatnonzero((f == 7).any(axis=1))[:2]
    f[seam] = np.where(f[seam] == 7, n + 6, f[seam])
    f = np.vstack([f, [[n, n + 2, n + 1], [n, n + 1, n + 3], [n, n + 3, n + 2], [n + 1, n + 2, n + 3]],
                   f[10:11], [[a, b, n + 5]]])
    return wolf, v, f


def test_every_repair_of_a_damaged_mesh_and_the_index_back_to_the_input():
    wolf, v, f = _damaged_wolf()
    assert {"components", "unreferenced-vertex", "duplicate-face", "zero-area-face"} <= set(_errors(v, f))
    out = repaired(v, f)
    assert _errors(out.vertices, out.faces) == []
    assert out.notes == ["welded 1 vertex into others at the same position", "dropped 1 face that has zero area",
                         "dropped 1 face that repeats another face",
                         f"kept the largest of 2 connected components by surface area ({len(wolf.vertices)} of "
                         f"{len(wolf.vertices) + 4} vertices in faces)", "dropped 2 vertices that no face uses"]
    # the wolf itself, vertex for vertex and face for face, and every vertex is the input's vertex it names
    assert np.array_equal(out.source_index, np.arange(len(wolf.vertices)))
    assert np.array_equal(out.vertices, v[out.source_index])
    assert np.array_equal(out.faces, wolf.faces)


def test_a_clean_mesh_is_left_as_it_is():
    wolf = load_mesh(TOSCA / "wolf1.off")
    out = repaired(wolf.vertices, wolf.faces)
    assert out.notes == [] and np.array_equal(out.faces, wolf.faces)
    assert np.array_equal(out.vertices, wolf.vertices) and np.array_equal(out.source_index, np.arange(len(wolf.vertices)))


def test_a_triangle_soup_is_welded_into_its_surface_and_turned_faces_agree():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    corners = sphere.vertices[sphere.faces].reshape(-1, 3)
    faces = np.arange(len(corners)).reshape(-1, 3)
    faces[::7] = faces[::7, ::-1]  # some faces turned
    out = repaired(corners, faces)
    assert len(out.vertices) == len(sphere.vertices) and len(out.faces) == len(sphere.faces)
    assert _errors(out.vertices, out.faces) == []
    assert np.allclose(out.vertices, corners[out.source_index])
    assert trimesh.Trimesh(out.vertices, out.faces, process=False).volume > 0  # outward, as most faces were
    assert out.notes[0] == f"welded {len(corners) - len(sphere.vertices)} vertices into others at the same position"
    assert out.notes[-1] == f"turned {len(faces[::7])} faces to agree with their neighbours' winding"


def test_what_has_no_repair_is_refused_by_name():
    sphere = trimesh.creation.icosphere(subdivisions=1)
    v, f = sphere.vertices, sphere.faces
    a, b = f[0, 0], f[0, 1]
    fin = (np.vstack([v, [[3.0, 3.0, 3.0]]]), np.vstack([f, [[a, b, len(v)]]]))  # a third face on an edge
    with pytest.raises(MeshError, match=r"fin.off: 1 edges are shared by more than two faces .* \(after the "
                                        r"repairs: none needed\)"):
        repaired(*fin, name="fin.off")
    broken = v.copy()
    broken[3] = np.nan
    with pytest.raises(MeshError, match=r"nan.off: 1 vertices have NaN .* \(no repair for this\)"):
        repaired(broken, f, name="nan.off")


def test_corr_repair_writes_the_mesh_and_the_input_vertices(tmp_path, capsys):
    wolf, v, f = _damaged_wolf()
    save_mesh(tmp_path / "damaged.ply", v, f)
    assert main(["match", str(tmp_path / "damaged.ply"), str(TOSCA / "wolf1.off"), "-o", str(tmp_path / "m")]) == 2
    assert "corr repair" in capsys.readouterr().err  # the loader's refusal names the command
    assert main(["repair", str(tmp_path / "damaged.ply"), "-o", str(tmp_path / "fixed.off")]) == 0
    text = capsys.readouterr().out
    assert "kept the largest of 2 connected components" in text and "fixed.source_vertices.txt" in text
    fixed = load_mesh(tmp_path / "fixed.off")
    index = np.loadtxt(tmp_path / "fixed.source_vertices.txt", dtype=int)
    assert np.allclose(fixed.vertices, read_mesh_arrays(tmp_path / "damaged.ply")[0][index])
    # refused before any work: the input as the output, a format that cannot be written, an unrepairable mesh
    assert main(["repair", str(tmp_path / "fixed.off"), "-o", str(tmp_path / "fixed.off")]) == 2
    assert "destroy the input" in capsys.readouterr().err
    assert main(["repair", str(tmp_path / "fixed.off"), "-o", str(tmp_path / "fixed.stl")]) == 2
    assert "-o must name a mesh file" in capsys.readouterr().err
    sphere = trimesh.creation.icosphere(subdivisions=1)
    a, b = sphere.faces[0, 0], sphere.faces[0, 1]
    save_mesh(tmp_path / "fin.off", np.vstack([sphere.vertices, [[3.0, 3.0, 3.0]]]),
              np.vstack([sphere.faces, [[a, b, len(sphere.vertices)]]]))
    assert main(["repair", str(tmp_path / "fin.off"), "-o", str(tmp_path / "fin_fixed.off")]) == 2
    assert "more than two faces" in capsys.readouterr().err
    assert not (tmp_path / "fin_fixed.off").exists() and not (tmp_path / "fin_fixed.source_vertices.txt").exists()


def test_an_inside_out_surface_is_turned_and_what_no_repair_removes_is_said(tmp_path, capsys):
    """Found by fuzzing: a closed surface inside out was left so; a Möbius strip (which no turning of faces
    orients) and two spheres welded at one point passed as "no repair was needed"."""
    sphere = trimesh.creation.icosphere(subdivisions=2)
    out = repaired(sphere.vertices, sphere.faces[:, ::-1])
    assert out.notes == ["turned every face so that the normals point outward (the closed surface was inside out)"]
    assert np.array_equal(out.faces, sphere.faces) and out.warnings == []
    count = 24
    rows = []
    for t in np.linspace(0, 2 * np.pi, count, endpoint=False):
        rows += [[(1 + w * np.cos(t / 2)) * np.cos(t), (1 + w * np.cos(t / 2)) * np.sin(t), w * np.sin(t / 2)]
                 for w in (-0.3, 0.3)]
    strip = []
    for i in range(count):  # the last quad joins the first edge turned over
        c, d = (2 * i + 2, 2 * i + 3) if i < count - 1 else (1, 0)
        strip += [[2 * i, 2 * i + 1, d], [2 * i, d, c]]
    save_mesh(tmp_path / "moebius.off", np.array(rows), np.array(strip))
    assert main(["repair", str(tmp_path / "moebius.off"), "-o", str(tmp_path / "fixed.off")]) == 0
    said = capsys.readouterr()
    assert "no repair was needed" in said.out and "warning: moebius.off: 1 interior edges join faces of " \
        "inconsistent orientation" in said.err, said
    touching = trimesh.util.concatenate([sphere, sphere.copy().apply_translation([2, 0, 0])])
    out = repaired(touching.vertices, touching.faces)
    assert out.notes == ["welded 1 vertex into others at the same position"]
    assert len(out.warnings) == 1 and "join separate fans of faces" in out.warnings[0]


def test_the_largest_component_is_the_largest_surface():
    """Found by fuzzing: the part with more vertices was kept, though the other had four times its area."""
    fine = trimesh.creation.icosphere(subdivisions=3)  # 642 vertices, area 4π
    coarse = trimesh.creation.icosphere(subdivisions=1).apply_scale(2.0).apply_translation([10, 0, 0])  # 42, 16π
    both = trimesh.util.concatenate([fine, coarse])
    out = repaired(both.vertices, both.faces)
    assert len(out.vertices) == len(coarse.vertices)
    assert out.notes == [f"kept the largest of 2 connected components by surface area ({len(coarse.vertices)} of "
                         f"{len(both.vertices)} vertices in faces)"]


def test_an_obj_face_beyond_the_file_s_vertices_is_named_as_the_file_counts(tmp_path, capsys):
    (tmp_path / "bad.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 9\n")
    assert main(["repair", str(tmp_path / "bad.obj"), "-o", str(tmp_path / "fixed.off")]) == 2
    assert "(vertex 9, counting from 1 as OBJ does; the file has 4 vertices)" in capsys.readouterr().err
