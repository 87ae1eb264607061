"""The 2D-to-3D benchmark: plane-section queries, their ground truth, scoring and the command."""

import json
import shutil

import numpy as np
import pytest
import scipy.sparse as sp
import trimesh
from scipy.sparse.csgraph import dijkstra

from _data import ROOT, TOSCA
from corrlib.cli import main
from corrlib.contour_bench import (_vts_transfer, contour_benchmark, contour_jobs, cut_query, match_cut_query,
                                   score_curve, silhouette_query, symmetry_normal)
from corrlib.errors import InputError, ParameterError
from corrlib.geometry.sections import plane_basis, principal_frame
from corrlib.io import load_mesh, load_vts
from corrlib.shapes import Contour2D, TriMesh


def ellipsoid_with_bump():
    """Axes 3 > 2 > 1 along x, y, z; a bump on +z keeps the mirror symmetry across y = 0 only."""
    sphere = trimesh.creation.icosphere(subdivisions=4)
    v = sphere.vertices * [3.0, 2.0, 1.0]
    v[:, 2] += 0.6 * np.exp(-((v[:, 0] - 1.0) ** 2 + v[:, 1] ** 2) / 0.5) * (v[:, 2] > 0)
    return TriMesh(v, sphere.faces, name="bumpy")


def test_planes_of_a_shape_with_one_mirror_symmetry():
    mesh = ellipsoid_with_bump()
    centre, axes = principal_frame(mesh)
    assert abs(axes[2] @ [0, 0, 1]) > 0.99  # main plane: spanned by (nearly) x and y
    assert abs(symmetry_normal(mesh) @ [0, 1, 0]) > 0.999  # mirror plane y = 0
    for plane, normal in (("main", axes[2]), ("symmetry", symmetry_normal(mesh)), ("cross", axes[1])):
        query = cut_query(mesh, plane)
        # the loop lies in its plane through the centroid
        assert np.allclose((query.points_3d - centre) @ normal, 0.0, atol=1e-9), plane
        assert query.contour.n_points > 50


def test_ground_truth_of_an_equator_cut_is_the_vertex_at_the_same_angle():
    sphere = trimesh.creation.icosphere(subdivisions=4)
    mesh = TriMesh(sphere.vertices * [2.0, 1.5, 1.0], sphere.faces, name="ellipsoid")
    query = cut_query(mesh, "main")
    centre, axes = principal_frame(mesh)
    _, u, v = plane_basis(axes[2])
    # arbitrary points along the contour: a resampling at 97 points
    points = query.contour.ccw().resample(97).points
    gt = query.ground_truth(points, mesh.vertices)
    rebuilt = np.column_stack([(mesh.vertices[gt] - centre) @ u, (mesh.vertices[gt] - centre) @ v])
    # within one edge length of the point (the nearer end of the edges the point lies between)
    assert np.max(np.linalg.norm(rebuilt - points, axis=1)) < mesh.edge_lengths.max()
    # and the ground-truth vertices lie next to the plane
    assert np.max(np.abs((mesh.vertices[gt] - centre) @ axes[2])) < 0.1


def test_score_of_the_ground_truth_is_perfect_and_of_a_collapsed_curve_is_not():
    wolf = load_mesh(TOSCA / "wolf0.off")
    query = cut_query(wolf, "main")
    points = query.contour.resample(150).points
    gt = query.ground_truth(points, wolf.vertices)
    # the ground truth as a closed edge path: shortest graph paths between consecutive ground-truth vertices
    e = wolf.edges
    graph = sp.coo_matrix((wolf.edge_lengths, (e[:, 0], e[:, 1])), shape=(wolf.n_vertices,) * 2).tocsr()
    _, pred = dijkstra(graph, directed=False, indices=gt, return_predecessors=True)
    path = [gt[0]]
    for k, b in enumerate(np.r_[gt[1:], gt[:1]]):
        hops = []
        while b != gt[k]:
            hops.append(b)
            b = pred[k, b]
        path += hops[::-1]
    perfect = score_curve(gt, np.array(path), gt, wolf, query.length_3d)
    assert perfect["mean_error"] == 0.0 and perfect["within_005"] == 1.0
    assert 0.9 < perfect["coverage"] < 1.6
    # a curve that runs back and forth on a short stretch: large error, small coverage
    short = np.r_[gt[:10], gt[9::-1]]
    collapsed_map = np.resize(short, len(gt))
    bad = score_curve(collapsed_map, short, gt, wolf, query.length_3d)
    assert bad["mean_error"] > 0.2 and bad["coverage"] < 0.3 and bad["distinct_vertices"] <= 10
    # several acceptable vertices: the error is the distance to the nearest of them
    either = np.column_stack([collapsed_map, gt])
    assert score_curve(collapsed_map, short, either, wolf, query.length_3d)["mean_error"] == 0.0
    alternative = score_curve(collapsed_map, short, np.column_stack([gt, gt]), wolf, query.length_3d)
    assert alternative["mean_error"] == pytest.approx(bad["mean_error"], rel=1e-12)
    # the share of the truth reached by the curve: all of it for the truth and for the truth traversed the other
    # way round (every point on the curve, the errors large); little of it for the short curve, and for a curve
    # crowded into the same stretch that wiggles back and forth until it is as long as the truth
    assert perfect["reached"] == 1.0 and bad["reached"] < 0.2
    backwards = score_curve(gt[::-1], np.array(path[::-1]), gt, wolf, query.length_3d)
    assert backwards["reached"] == 1.0 and backwards["mean_error"] > 0.2
    repeats = int(np.ceil(perfect["coverage"] / bad["coverage"]))
    wiggle = np.r_[np.tile(short[:-1], repeats), short[-1]]
    crowded = score_curve(collapsed_map, wiggle, gt, wolf, query.length_3d)
    assert crowded["coverage"] >= perfect["coverage"] and crowded["reached"] == bad["reached"]


def test_jobs_pair_each_mesh_with_itself_and_its_class(tmp_path):
    for name in ("wolf0", "wolf1", "cat0"):
        shutil.copy(TOSCA / f"{name}.off", tmp_path / f"{name}.off")
    jobs = contour_jobs([tmp_path], planes=("main",))
    pairs = sorted((j.source.stem, j.target.stem) for j in jobs)
    assert pairs == [("cat0", "cat0"), ("wolf0", "wolf0"), ("wolf0", "wolf1"), ("wolf1", "wolf0"), ("wolf1", "wolf1")]
    with pytest.raises(ParameterError, match="plane"):
        contour_jobs([tmp_path], planes=("diagonal",))


def test_vts_ground_truth_carries_the_section_to_the_other_pose(tmp_path):
    """The section of cat0 carried to cat1 through the .vts rows stays a coherent curve of about its length."""
    for name in ("cat0", "cat1"):
        shutil.copy(TOSCA / f"{name}.off", tmp_path / f"{name}.off")
        shutil.copy(TOSCA / f"{name}.vts", tmp_path / f"{name}.vts")
    job = next(j for j in contour_jobs([tmp_path], planes=("cross",)) if (j.source.stem, j.target.stem) ==
               ("cat0", "cat1"))
    cat0, cat1 = load_mesh(job.source), load_mesh(job.target)
    query = cut_query(cat0, "cross")
    gt0 = query.ground_truth(query.contour.resample(200).points, cat0.vertices)
    gt1 = _vts_transfer(cat0.vertices, *job.gt_rows)(gt0)
    length1 = np.linalg.norm(np.roll(cat1.vertices[gt1], -1, axis=0) - cat1.vertices[gt1], axis=1).sum()
    expected = query.length_3d * np.sqrt(cat1.area / cat0.area)
    assert 0.8 * expected < length1 < 1.5 * expected, (length1, expected)


@pytest.mark.slow
def test_benchmark_end_to_end_with_vts_ground_truth(tmp_path):
    data = tmp_path / "cats"
    data.mkdir()
    for name in ("cat0", "cat1"):
        shutil.copy(TOSCA / f"{name}.off", data / f"{name}.off")
        shutil.copy(TOSCA / f"{name}.vts", data / f"{name}.vts")
        shutil.copy(TOSCA / f"{name}.sym.vts", data / f"{name}.sym.vts")
    assert all(job.mirror_rows is not None for job in contour_jobs([data], planes=("main",)))
    out = tmp_path / "out"
    rows = []
    summary = contour_benchmark([data], out, planes=("main",), params={"n_contour": 60, "eps": 0.05}, jobs=1,
                                callback=lambda done, total, row: rows.append(row))
    assert len(rows) == 4 and all(r["status"] == "ok" for r in rows)
    assert summary["same mesh"]["queries"] == 2 and summary["other pose"]["queries"] == 2
    for r in rows:
        assert 0 <= r["mean_error"] < 1 and r["coverage"] > 0 and r["distinct_vertices"] > 1
        assert 0 <= r["mean_error_sym"] <= r["mean_error"]
        assert r["n_points"] == 60 and r["gap"] >= 0
        # a section through the plane of symmetry is a side view, read as the half model
        assert (r["view"], r["model"]) == ("side", "half")
    written = json.loads((out / "contour_summary.json").read_text())
    assert written["summary"]["all"]["queries"] == 4
    csv_lines = (out / "contour_bench.csv").read_text().splitlines()
    assert len(csv_lines) == 5 and "view,model" in csv_lines[0]
    assert len(list((out / "pictures").glob("*.png"))) == 4
    assert "| other pose |" in (out / "contour_summary.md").read_text()
    assert "mirror accepted" in (out / "contour_summary.md").read_text()


def test_command_and_its_errors(tmp_path, capsys):
    data = tmp_path / "wolves"
    data.mkdir()
    shutil.copy(TOSCA / "wolf0.off", data / "wolf0.off")
    assert main(["bench-contour", str(data), "--planes", "main", "--n-contour", "40", "--param", "eps=0.1",
                 "--jobs", "1", "--no-pictures", "-q", "-o", str(tmp_path / "out")]) == 0
    assert "| same mesh | 1 | 0 |" in capsys.readouterr().out
    assert not (tmp_path / "out" / "pictures").exists()
    # bad input: named errors, exit 2, before any work
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["bench-contour", str(data), "-o", str(blocker / "out")]) == 2
    assert "cannot write output" in capsys.readouterr().err
    assert main(["bench-contour", str(data), "--planes", "oblique", "-o", str(tmp_path / "o2")]) == 2
    assert "plane must be one of" in capsys.readouterr().err
    assert main(["bench-contour", str(data), "--param", "k=-3", "-o", str(tmp_path / "o3")]) == 2
    assert "k" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stopped:  # refused by the parser, naming the option
        main(["bench-contour", str(data), "--jobs", "-1", "-o", str(tmp_path / "o4")])
    assert stopped.value.code == 2
    assert "argument --jobs: expected 0 (all cores) or a positive number" in capsys.readouterr().err
    with pytest.raises(ParameterError, match="jobs must be 0 or None .* got -1"):  # and by the library
        contour_benchmark([data], tmp_path / "o4", planes=["main"], jobs=-1)
    assert not any((tmp_path / name).exists() for name in ("o2", "o3", "o4"))


def test_a_plane_that_cuts_nothing_closed_is_a_named_error():
    # an open strip: its sections are open chains, not loops
    grid = trimesh.creation.box(extents=[4.0, 1.0, 0.2])
    strip = TriMesh(grid.vertices, grid.faces[grid.face_normals[:, 2] > 0.5], validate=False, name="strip")
    with pytest.raises(InputError, match="strip.*closed section loop"):
        cut_query(strip, "main")


@pytest.mark.slow
def test_cross_class_map_files_add_pairs_with_their_ground_truth(tmp_path, capsys):
    """``<a>2<b>`` (as the Sumner lion -> cat map is shipped) or ``<a>__<b>.txt``, by shape or by class."""
    shutil.copy(TOSCA / "wolf0.off", tmp_path / "wolf0.off")
    shutil.copy(TOSCA / "wolf1.off", tmp_path / "dog-7.off")  # another 'class' with the wolf's connectivity
    n = load_mesh(TOSCA / "wolf0.off").n_vertices
    reversed_map = np.arange(n)[::-1]
    np.savetxt(tmp_path / "wolf2dog", reversed_map, fmt="%d")
    jobs = contour_jobs([tmp_path], planes=("main",))
    cross = [j for j in jobs if (j.source.stem, j.target.stem) == ("wolf0", "dog-7")]
    assert len(cross) == 1 and np.array_equal(cross[0].gt_map, reversed_map)
    # the identity map, through the benchmark: the same figures as the identical-connectivity pair
    np.savetxt(tmp_path / "wolf2dog", np.arange(n), fmt="%d")
    summary = contour_benchmark([tmp_path], tmp_path / "out", planes=("main",), params={"n_contour": 40, "eps": 0.1},
                                jobs=1, pictures=False)
    rows = json.loads((tmp_path / "out" / "contour_summary.json").read_text())["rows"]
    cross_row = next(r for r in rows if r["other_class"])
    assert summary["other class"]["queries"] == 1 and cross_row["status"] == "ok"
    direct = match_cut_query(str(tmp_path / "wolf0.off"), str(tmp_path / "dog-7.off"), "main",
                             {"n_contour": 40, "eps": 0.1})  # no map: identical connectivity
    assert direct["status"] == "ok" and cross_row["mean_error"] == pytest.approx(direct["mean_error"], rel=1e-12)
    # a map of the wrong length is a named error naming the file
    np.savetxt(tmp_path / "wolf2dog", np.arange(n - 5), fmt="%d")
    with pytest.raises(InputError, match="wolf2dog.*entries"):
        contour_jobs([tmp_path], planes=("main",))


@pytest.mark.parametrize("view, depth_axis", [("silhouette", 2), ("top", 1)])
def test_silhouette_ground_truth_lies_on_the_outline_and_is_near_and_far_side(view, depth_axis):
    """Rim vertices project within the search radius of their outline point; the near-side one is never
    deeper than the far-side one; the outline length in mesh units is about the projection's perimeter.
    The side view looks along the axis of least variance, the top view along the middle one."""
    wolf = load_mesh(TOSCA / "wolf0.off")
    query = silhouette_query(wolf, view=view)
    assert query.plane == view
    _, axes = principal_frame(wolf)
    assert np.ptp(query.projection.depth) == pytest.approx(np.ptp(wolf.vertices @ axes[depth_axis]), rel=1e-9)
    points = query.contour.resample(150).points
    rim = query.ground_truth(points, wolf.vertices)
    pixels, depth = query.projection.pixels, query.projection.depth
    assert rim.shape == (150, 2)
    from scipy.spatial import cKDTree

    nearest = cKDTree(pixels).query(points)[0]  # the fallback where no vertex lies within 3 pixels
    for side in (0, 1):
        assert np.all(np.linalg.norm(pixels[rim[:, side]] - points, axis=1) <= np.maximum(3.0, nearest) + 1e-9)
    # every outline point has a vertex within an edge length (the outline runs along projected faces)
    assert nearest.max() <= wolf.edge_lengths.max() * query.projection.pixels_per_unit
    assert np.all(depth[rim[:, 0]] <= depth[rim[:, 1]])
    # the outline encloses the projection of every vertex (up to the rasterisation)
    from matplotlib.path import Path as PolygonPath

    inside = PolygonPath(query.contour.points).contains_points(pixels, radius=2.0)
    assert inside.mean() > 0.99
    extent = (pixels.max(axis=0) - pixels.min(axis=0)) / query.projection.pixels_per_unit
    assert 2 * extent.max() < query.length_3d < 4 * extent.sum()


def test_an_unknown_silhouette_view_is_a_named_error():
    with pytest.raises(ParameterError, match="unknown silhouette view 'back'"):
        silhouette_query(load_mesh(TOSCA / "wolf0.off"), view="back")


@pytest.mark.slow
def test_silhouette_queries_end_to_end(tmp_path):
    """Side-view silhouettes of the wolves matched to both poses (120 points). Measured with the half-shape
    model and one axis (the previous defaults): mean error 0.073-0.078, 75-84 % within 0.1, coverage 0.80-0.91 (the nearer of the
    near- and far-side rim vertex scored); model=whole: 0.081-0.098, 59-76 %; the paper's cost
    (features=paper, axis_weight=0, model=flat) gives 0.10-0.11 on the wolves, 0.21-0.40 on the cats."""
    data = tmp_path / "wolves"
    data.mkdir()
    for name in ("wolf0", "wolf1"):
        shutil.copy(TOSCA / f"{name}.off", data / f"{name}.off")
    rows = []
    summary = contour_benchmark([data], tmp_path / "out", planes=("silhouette",), params={"n_contour": 120},
                                jobs=1, pictures=False, callback=lambda done, total, row: rows.append(row))
    assert len(rows) == 4 and all(r["status"] == "ok" for r in rows), rows
    assert summary["other pose"]["queries"] == 2
    for r in rows:
        assert r["query"].endswith("-silhouette")
        assert r["mean_error"] < 0.1 and r["within_01"] > 0.65 and r["coverage"] > 0.7, r


@pytest.mark.slow
@pytest.mark.parametrize("plane, half_below", [("silhouette", 0.09), ("main", 0.25)])
def test_half_shape_model_beats_the_whole_surface_on_the_other_pose_of_the_cat(plane, half_below):
    """cat0's queries matched to cat1 (remeshed independently, .vts ground truth), one axis, the paper's
    Euclidean product metric (with the max metric both models reach 0.06-0.08 on the section). Measured:
    silhouette 0.070 (half) against 0.098 (whole), main-plane section 0.195 against 0.304."""
    gt_rows = (load_vts(TOSCA / "cat0.vts"), load_vts(TOSCA / "cat1.vts"))
    errors = {model: match_cut_query(TOSCA / "cat0.off", TOSCA / "cat1.off", plane, {"model": model, "axis_modes": 1,
                                                                                  "metric": "euclidean"},
                                     gt_rows=gt_rows)["mean_error"] for model in ("half", "whole")}
    assert errors["half"] < half_below and errors["half"] < errors["whole"], errors


@pytest.mark.slow
def test_a_target_coarser_than_the_contour_is_matched_with_fewer_points(tmp_path, wolf1_quarter):
    """wolf0's main section on wolf1 decimated to a quarter of its vertices (an uneven mesh whose mean edge is
    about twice the step of 200 contour points): the contour is resampled to the mesh's edge length, so that a
    step can keep pace with an edge. With 200 points the tail was cut short (coverage 0.81) and the curve
    matched 0.25 √area off, measured."""
    from corrlib.io import save_mesh

    target, truth = wolf1_quarter
    path = save_mesh(tmp_path / "wolf1_quarter.off", target.vertices, target.faces)
    row = match_cut_query(TOSCA / "wolf0.off", path, "main", {"mesh_vertices": 0}, gt_map=truth)  # as given
    assert row["status"] == "ok", row
    assert row["mean_error"] < 0.08 and row["coverage"] > 0.9, row


def test_the_contour_is_resampled_only_for_a_mesh_coarser_than_its_step():
    """The number of points follows the mesh's mean edge (a 1:4 subdivision halves it: twice the points); on a
    mesh finer than the contour's step the query is matched as prepared."""
    from corrlib.methods.contour3d import Contour3DParams, contour_points_for, prepare_query, query_for_mesh

    sphere = trimesh.creation.icosphere(subdivisions=3)
    coarse = TriMesh(sphere.vertices, sphere.faces, name="coarse")
    fine = TriMesh(*trimesh.remesh.subdivide(sphere.vertices, sphere.faces), name="fine")
    angle = np.linspace(0.0, 2.0 * np.pi, 400, endpoint=False)
    ellipse = Contour2D(np.c_[2.0 * np.cos(angle), np.sin(angle)], name="ellipse")
    params = Contour3DParams(n_contour=200, k=10)
    query = prepare_query(ellipse, params)
    n_coarse, n_fine = contour_points_for(query, coarse), contour_points_for(query, fine)
    ratio = (np.mean(coarse.edge_lengths) / np.sqrt(coarse.area)) / (np.mean(fine.edge_lengths) / np.sqrt(fine.area))
    assert abs(n_fine / n_coarse - ratio) < 0.05 and 1.9 < ratio < 2.1
    assert n_coarse < 200
    fitted = query_for_mesh(query, coarse, params)
    assert len(fitted.points) == n_coarse and fitted.source is ellipse
    assert query_for_mesh(query, TriMesh(*trimesh.remesh.subdivide(fine.vertices, fine.faces), name="finer"),
                          params) is query


def test_mirrored_ground_truth_is_an_involution_away_from_the_symmetry_curve():
    """The mirror of the cat's section ground truth (through .vts and .sym.vts rows) is another curve (the
    other flank), and mirroring twice gives back the original up to the sparse rows' spacing."""
    from corrlib.geometry.geodesics import GeodesicSolver
    from corrlib.io import load_vts

    cat = load_mesh(TOSCA / "cat0.off")
    rows, sym_rows = load_vts(TOSCA / "cat0.vts"), load_vts(TOSCA / "cat0.sym.vts")
    query = cut_query(cat, "cross")
    gt = query.ground_truth(query.contour.resample(100).points, cat.vertices)
    mirror = _vts_transfer(cat.vertices, rows, sym_rows)
    solver = GeodesicSolver(cat)
    scale = np.sqrt(cat.area)
    assert np.mean(solver.pair_distances(gt, mirror(gt))) / scale > 0.05
    assert np.mean(solver.pair_distances(gt, mirror(mirror(gt)))) / scale < 0.02


@pytest.mark.slow
def test_a_person_seen_from_the_front_is_matched_to_other_poses(tmp_path):
    """The front silhouette of a synthetic person in the rest pose (tests/_humanoid.py: two arms and two
    legs in one outline) matched to two other poses. Features that cannot tell left from right let the
    curve run out and back along one arm for both arms of the outline; the second intrinsic axis (left to
    right) prevents it, and so does keeping each half of the outline on its own half of the surface
    (front_curve=sided). Measured, mirror accepted (a front view cannot tell left from right): 0.045 and
    0.061 with the defaults (model=auto, two axes, sided); with one axis 0.045 sided (human1), 0.31-0.34 free."""
    from _humanoid import write_dataset

    data = write_dataset(tmp_path / "people")
    jobs = [j for j in contour_jobs([data], planes=("silhouette",)) if j.source.stem == "human0"]
    assert len(jobs) == 3 and all(j.mirror_rows is not None for j in jobs)
    for job in jobs:
        if job.target.stem == "human0":
            continue
        row = match_cut_query(job.source, job.target, "silhouette", {}, gt_rows=job.gt_rows,
                              mirror_rows=job.mirror_rows)
        assert row["status"] == "ok", row
        assert row["mean_error_sym"] < 0.08 and row["coverage"] > 0.8, row
        free = match_cut_query(job.source, job.target, "silhouette", {"axis_modes": 1, "front_curve": "free"},
                               gt_rows=job.gt_rows, mirror_rows=job.mirror_rows)
        assert free["mean_error_sym"] > 0.2, free
    to_human1 = next(j for j in jobs if j.target.stem == "human1")
    sided = match_cut_query(to_human1.source, to_human1.target, "silhouette", {"axis_modes": 1},
                            gt_rows=to_human1.gt_rows, mirror_rows=to_human1.mirror_rows)
    assert sided["mean_error_sym"] < 0.08, sided


@pytest.mark.slow
def test_a_posed_person_seen_from_the_front_is_a_front_view():
    """The bundled posed person (resources/people/human3: one arm lowered by 69 degrees, the other raised,
    legs apart, head turned) seen from the front is not its own mirror image in 2D, but its outline keeps its
    intrinsic symmetry, so view=auto takes it for a front view (the whole surface). Matched to the rest pose
    (same vertices; mirror accepted, a front view cannot tell left from right), measured: 0.061. (Read as a
    side view it was 0.298 while the rest pose's computed reflection was its front–back near-symmetry; with
    the sign-searched reflection that reading finds the same curve, 0.060, at a higher energy.)"""
    from _humanoid import humanoids

    from corrlib.contour_bench import silhouette_query
    from corrlib.io import load_mesh
    from corrlib.methods import solve
    from corrlib.resources import resource

    people = resource("people")
    _, mirror = humanoids()
    rows = np.arange(len(mirror))
    front = match_cut_query(people / "human3.off", people / "human0.off", "silhouette", {}, gt_rows=(rows, rows),
                            mirror_rows=(rows, mirror))
    assert front["status"] == "ok" and front["mean_error_sym"] < 0.08 and front["coverage"] > 0.8, front
    query = silhouette_query(load_mesh(people / "human3.off"))
    result = solve("contour3d", query.contour, load_mesh(people / "human0.off"))
    assert result.extras["view"] == "front" and result.extras["model"] == "whole", result.extras


@pytest.mark.slow
def test_a_bent_person_is_not_read_as_a_side_view_where_the_mesh_is_a_person(tmp_path):
    """The front silhouette of the person with bent arms and legs (tests/_humanoid.py, human1) is asymmetric in
    2D and intrinsically, so the outline alone takes it for a side view and reads it as half the surface; but
    a person is thinnest from front to back, so matched to a person (view=auto) it is a front view, and each
    half of the outline keeps to its own half of the surface (front_curve=sided). Measured against the rest
    pose, mirror accepted: 0.050 with the defaults, 0.164 with front_curve=free (down one flank and back),
    0.350 with view=outline."""
    from _humanoid import write_dataset

    from corrlib.contour_bench import silhouette_query
    from corrlib.methods import solve

    people = write_dataset(tmp_path / "people")
    jobs = {j.target.stem: j for j in contour_jobs([people], planes=("silhouette",)) if j.source.stem == "human1"}
    job = jobs["human0"]
    mesh_aware = match_cut_query(job.source, job.target, "silhouette", {}, gt_rows=job.gt_rows,
                                 mirror_rows=job.mirror_rows)
    outline = match_cut_query(job.source, job.target, "silhouette", {"view": "outline"}, gt_rows=job.gt_rows,
                              mirror_rows=job.mirror_rows)
    free = match_cut_query(job.source, job.target, "silhouette", {"front_curve": "free"}, gt_rows=job.gt_rows,
                           mirror_rows=job.mirror_rows)
    assert mesh_aware["mean_error_sym"] < 0.08 and mesh_aware["coverage"] > 0.8, mesh_aware
    assert free["mean_error_sym"] > mesh_aware["mean_error_sym"] + 0.05, free
    assert outline["mean_error_sym"] > mesh_aware["mean_error_sym"] + 0.1, outline
    query = silhouette_query(load_mesh(job.source))
    extras = solve("contour3d", query.contour, load_mesh(job.target), n_contour=40).extras
    assert extras["view"] == "front" and extras["mesh_seen_from_side"] is False, extras
    assert solve("contour3d", query.contour, load_mesh(job.target), n_contour=40,
                 view="outline").extras["view"] == "side"


@pytest.mark.slow
def test_a_section_through_the_plane_of_symmetry_follows_the_curve_of_symmetry(tmp_path):
    """The wolf's main-plane section (a side view) matched to the wolf in another pose and to that pose's mirror
    image: with the side-view terms the curve runs along the curve of symmetry, once round the body (measured
    0.047 mean error, coverage 0.99); without them (view="front", the previous default) it ran along a flank
    (0.175). The mirror image of the target gives the same error (both halves are searched)."""
    from corrlib.io import save_mesh

    wolf1 = load_mesh(TOSCA / "wolf1.off")
    mirrored = tmp_path / "wolf1m.off"
    save_mesh(mirrored, wolf1.vertices * [-1.0, 1.0, 1.0], wolf1.faces[:, ::-1])
    side = match_cut_query(TOSCA / "wolf0.off", TOSCA / "wolf1.off", "main", {})
    assert side["status"] == "ok" and side["mean_error"] < 0.06 and side["coverage"] > 0.9, side
    flipped = match_cut_query(TOSCA / "wolf0.off", mirrored, "main", {})
    assert flipped["mean_error"] == pytest.approx(side["mean_error"], abs=0.01), flipped
    front = match_cut_query(TOSCA / "wolf0.off", TOSCA / "wolf1.off", "main", {"view": "front"})
    assert front["mean_error"] > 0.1, front


def test_the_view_is_read_off_the_outline():
    """A mirror-symmetric outline (an ellipse: a view within the plane of symmetry) gets no side-view terms,
    the wolf's section does; the choice is recorded with the outline's asymmetry."""
    from corrlib.methods import solve
    from corrlib.shapes import Contour2D

    wolf = load_mesh(TOSCA / "wolf0.off")
    t = np.linspace(0, 2 * np.pi, 120, endpoint=False)
    ellipse = Contour2D(np.column_stack([2 * np.cos(t), np.sin(t)]), name="ellipse")
    front = solve("contour3d", ellipse, wolf, n_contour=40)
    assert front.extras["view"] == "front" and front.extras["asymmetry"] < 0.01
    side = solve("contour3d", cut_query(wolf, "main").contour, wolf, n_contour=40)
    assert side.extras["view"] == "side" and side.extras["asymmetry"] > 0.03
    assert "side view" in side.energy_meaning
    forced = solve("contour3d", ellipse, wolf, n_contour=40, view="side")
    assert forced.extras["view"] == "side" and forced.energy > front.energy


# ----------------------------------------------------------------------------- labelled sketches


def _square_sketch(folder, name="square_sketch"):
    """A unit square outline and its triangulation, left half labelled 1, right half 2, the middle 0."""
    folder.mkdir(parents=True, exist_ok=True)
    xs = np.linspace(0.0, 1.0, 11)
    grid = np.array([(x, y, 0.0) for y in xs for x in xs])
    faces = [(r * 11 + c, r * 11 + c + 1, (r + 1) * 11 + c + 1) for r in range(10) for c in range(10)]
    faces += [(r * 11 + c, (r + 1) * 11 + c + 1, (r + 1) * 11 + c) for r in range(10) for c in range(10)]
    trimesh.Trimesh(grid, faces, process=False).export(folder / f"{name}.off")
    labels = np.where(grid[:, 0] < 0.45, 1, np.where(grid[:, 0] > 0.55, 2, 0))
    np.savetxt(folder / f"{name}_segmentation.txt", labels, fmt="%d", header="part label per vertex")
    t = np.linspace(0.0, 1.0, 10, endpoint=False)
    outline = np.vstack([np.c_[t, 0 * t], np.c_[1 + 0 * t, t], np.c_[1 - t, 1 + 0 * t], np.c_[0 * t, 1 - t]])
    np.savetxt(folder / f"{name}_contour.txt", outline)
    return folder


def test_part_agreement_counts_the_points_labelled_on_both_sides():
    from corrlib.contour_bench import part_agreement

    assert part_agreement([1, 1, 2, 2, 0, 3], [1, 2, 2, 0, 5, 3]) == (0.75, 4)  # 0 on either side: not scored
    agreement, scored = part_agreement([0, 0], [1, 2])
    assert np.isnan(agreement) and scored == 0


def test_sketch_points_take_the_label_of_the_nearest_sketch_vertex(tmp_path):
    from corrlib.contour_bench import sketch_queries

    (query,) = sketch_queries(_square_sketch(tmp_path / "sketches"))
    assert query.name == "square_sketch"
    assert list(query.point_labels([(0.0, 0.3), (1.0, 0.7), (0.5, 1.0), (0.31, 0.0)])) == [1, 2, 0, 1]


def test_incomplete_sketches_and_unlabelled_meshes_are_named_errors(tmp_path):
    from corrlib.contour_bench import sketch_jobs, sketch_queries
    from corrlib.errors import FileFormatError

    sketches = _square_sketch(tmp_path / "sketches")
    (sketches / "square_sketch_segmentation.txt").unlink()
    with pytest.raises(FileFormatError, match="square_sketch_contour.txt.*square_sketch_segmentation.txt"):
        sketch_queries(sketches)
    with pytest.raises(FileFormatError, match="no sketches"):
        sketch_queries(tmp_path)
    data = tmp_path / "wolves"
    data.mkdir()
    shutil.copy(TOSCA / "wolf0.off", data / "wolf0.off")
    with pytest.raises(InputError, match="wolves.*part labels.*wolf0|part labels"):
        sketch_jobs([data], [_square_sketch(tmp_path / "good")])
    assert sketch_jobs([data], []) == []
    # label files of the wrong length, of a sketch or of a mesh: named before any matching
    bad = _square_sketch(tmp_path / "bad")
    np.savetxt(bad / "square_sketch_segmentation.txt", [1, 2, 0], fmt="%d")
    with pytest.raises(FileFormatError, match="square_sketch_segmentation.txt.*3 labels, expected 121"):
        sketch_queries(bad)
    np.savetxt(data / "wolf0_segmentation.txt", [1, 2], fmt="%d")
    with pytest.raises(FileFormatError, match="wolf0_segmentation.txt.*2 labels"):
        sketch_jobs([data], [_square_sketch(tmp_path / "good")])


def test_sketch_command_errors_exit_2_before_any_output(tmp_path, capsys):
    data = tmp_path / "wolves"
    data.mkdir()
    shutil.copy(TOSCA / "wolf0.off", data / "wolf0.off")
    out = tmp_path / "out"
    assert main(["bench-contour", str(data), "--planes", "none", "-o", str(out)]) == 2
    assert "nothing to run" in capsys.readouterr().err
    assert main(["bench-contour", str(data), "--sketches", str(tmp_path / "missing"), "-o", str(out)]) == 2
    assert "missing: not a folder" in capsys.readouterr().err
    assert main(["bench-contour", str(data), "--planes", "none", "--sketches", str(_square_sketch(tmp_path / "sk")),
                 "-o", str(out)]) == 2
    assert "part labels" in capsys.readouterr().err
    assert not out.exists()


def test_the_people_carry_the_sketches_part_labels():
    """Every part of the sketches' vocabulary is present, and the mirror image of a left limb is the right one."""
    from _humanoid import humanoids, part_labels

    shapes, mirror = humanoids()
    labels = part_labels(shapes["human0"][0])
    assert set(np.unique(labels)) == {0, 1, 2, 3, 4, 5, 6, 7}
    swap = np.array([0, 2, 1, 3, 6, 5, 4, 7])  # legs 1 <-> 2, arms 4 <-> 6
    limbs = np.isin(labels, [1, 2, 4, 6])
    assert np.mean(labels[mirror][limbs] == swap[labels[limbs]]) > 0.99


@pytest.mark.slow
def test_the_papers_sketches_find_the_body_parts_of_a_person(tmp_path, capsys):
    """The two human sketches of the CVPR 2016 paper (resources/data/sketch2d, part labels of their own)
    matched to two poses of the synthetic person, whose labels follow the sketches' vocabulary; the labels
    are only scored. Measured: 0.91-0.93 of the labelled points on the right part (mirror accepted: a front
    view cannot tell left from right), the same with the sketch mirrored, reversed or scaled, and on the
    person remeshed, shuffled, mirrored or with vertex noise (docs/decisions.md). Swapping the person's arm
    and leg labels must show up as a low agreement."""
    from _humanoid import write_dataset
    from corrlib.resources import resource

    data = write_dataset(tmp_path / "people")
    (data / "human2.off").unlink()
    out = tmp_path / "out"
    assert main(["bench-contour", str(data), "--planes", "none", "--sketches", str(resource("data/sketch2d")),
                 "--jobs", "1", "-q", "-o", str(out)]) == 0
    assert "| sketches | n |" in capsys.readouterr().out
    result = json.loads((out / "contour_summary.json").read_text())
    rows = result["sketch_rows"]
    assert len(rows) == 4 and all(r["status"] == "ok" and r["optimal"] for r in rows)
    for row in rows:
        # distinct input vertices: the curve on the remeshed person, mapped to its nearest input vertices
        # (measured 188 and more; the collapsed curves of the paper's energy visited 62)
        assert row["part_agreement_sym"] >= 0.85 and row["distinct_vertices"] > 150, row
    assert result["summary"]["sketches"]["worst_part_agreement_sym"] >= 0.85
    assert len(list((out / "pictures").glob("human_sketch_*__human*.png"))) == 4
    # the score can fail: the person's arms labelled as legs and the legs as arms
    labels = np.loadtxt(data / "human1_segmentation.txt", dtype=int)
    swapped = np.array([0, 4, 6, 3, 1, 5, 2, 7])[labels]
    np.savetxt(data / "human1_segmentation.txt", swapped, fmt="%d")
    from corrlib.contour_bench import match_sketch_query, sketch_queries

    (sketch_a, _) = sketch_queries(resource("data/sketch2d"))
    row = match_sketch_query(sketch_a, data / "human1.off", data / "human1_segmentation.txt", {},
                             mirror_rows=(load_vts(data / "human1.vts"), load_vts(data / "human1.sym.vts")))
    assert row["part_agreement_sym"] < 0.6, row


def test_the_view_set_turns_the_side_view_about_the_vertical_axis():
    """``scripts/retrieval_views.py``: azimuth turns the side view (least-variance axis) about the vertical
    principal axis towards the other horizontal one, elevation towards the vertical."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("retrieval_views", ROOT / "scripts" / "retrieval_views.py")
    views = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(views)
    axes = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))[0].T  # rows: an orthonormal frame
    for vertical, horizontal in ((1, 0), (0, 1)):  # a quadruped's height, a person's height
        assert np.allclose(views.view_direction(axes, vertical, 0, 0), axes[2])
        assert np.allclose(views.view_direction(axes, vertical, 90, 0), axes[horizontal])
        assert np.allclose(views.view_direction(axes, vertical, 0, 90), axes[vertical])
        d = views.view_direction(axes, vertical, 30, 30)
        assert np.linalg.norm(d) == pytest.approx(1.0)
        assert d @ axes[vertical] == pytest.approx(0.5)  # elevation 30°
        level = d - (d @ axes[vertical]) * axes[vertical]
        assert level @ axes[2] / np.linalg.norm(level) == pytest.approx(np.cos(np.radians(30)))


def test_the_drawn_set_names_a_class_of_the_collection_for_every_drawing(tmp_path):
    """``scripts/retrieval_set.py --drawn``: every bundled drawing becomes a query in the subfolder of its class, a
    class the collection holds (else its average precision is undefined), the outline a simple polygon; a second
    run into the same folder stops with a named error before writing."""
    import importlib.util

    from corrlib.io import load_contour
    from corrlib.retrieval import class_of, files_under
    from corrlib.shapes import inspect_contour

    spec = importlib.util.spec_from_file_location("retrieval_set", ROOT / "scripts" / "retrieval_set.py")
    sets = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(sets)
    sets.drawn_main(tmp_path)
    queries = files_under(tmp_path / "queries", {".txt"}, "queries")
    classes = {class_of(mesh) for mesh in (tmp_path / "collection").glob("*.off")}
    assert len(queries) == len(sets.drawings()) == 7
    assert {class_of(query, tmp_path / "queries") for query in queries} == {"cat", "wolf", "lion", "human"} <= classes
    assert {query.name for query in queries} == {drawing.name for drawing in sets.drawings()}
    for query in queries:
        outline = load_contour(query)
        assert outline.points.shape[0] >= 20 and inspect_contour(outline.points) == [], query.name
    with pytest.raises(SystemExit):
        sets.drawn_main(tmp_path)


def test_an_approximate_search_returns_the_same_curve_on_any_thread():
    """With ``eps > 0`` the branch-and-bound may stop at any closed path within ``1 + eps`` of the optimum, so
    which one it returns depends on the order in which it searches the graphs. That order does not depend on
    the thread count, nor on whether the search runs on the main thread (the command line) or on a job's
    thread (the studio), so one input gives one curve everywhere. (On wolf0's section, one search at a time
    used to stop at a path of error 0.50 where two found one of 0.25.)"""
    from concurrent.futures import ThreadPoolExecutor

    import numba

    wolf0, wolf1 = str(TOSCA / "wolf0.off"), str(TOSCA / "wolf1.off")
    params = {"n_contour": 40, "eps": 0.1}
    results = []
    threads = numba.get_num_threads()
    try:
        for count in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
            numba.set_num_threads(count)
            results.append(match_cut_query(wolf0, wolf1, "main", params))
    finally:
        numba.set_num_threads(threads)
    with ThreadPoolExecutor(1) as pool:  # a job's thread: one backward search at a time
        results.append(pool.submit(match_cut_query, wolf0, wolf1, "main", params).result())
    assert all(r["status"] == "ok" for r in results)
    assert len({(r["energy"], r["mean_error"]) for r in results}) == 1
