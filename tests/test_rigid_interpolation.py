"""As-rigid-as-possible interpolation (corrlib.deformation.rigid_interpolation) and the sequences of corrlib.morph:
analytic motions, the identities it is built on, exact ends, and maps that snap to another mesh."""

import re

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from corrlib.deformation.rigid_interpolation import (deformation_gradients, polar_parts, rigid_interpolation,
                                                      unwrapped_rotation_vectors)
from corrlib.errors import InputError
from corrlib.geometry.laplacian import cotan_stiffness, gradient_operator, harmonic_extension, hat_gradients
from corrlib.shapes import signed_volume


def edge_lengths(vertices, faces):
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1)


def area_centroid(vertices, faces):
    p = vertices[faces]
    areas = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    lumped = np.zeros(len(vertices))
    for corner in range(3):
        np.add.at(lumped, faces[:, corner], areas / 3)
    return lumped @ vertices / lumped.sum()


@pytest.fixture(scope="module")
def capsule():
    mesh = trimesh.creation.capsule(height=2.0, radius=0.4, count=[16, 16])
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)


def test_hat_gradients_are_the_cotangent_stiffness_and_differentiate_linear_functions(capsule):
    vertices, faces = capsule
    hat, areas = hat_gradients(vertices, faces)
    assert np.allclose(hat.sum(axis=1), 0, atol=1e-9)  # the hat functions sum to one on every face
    # Σ_f A_f ∇φ_i·∇φ_j is the cotangent stiffness (an independent assembly from the angles)
    stiffness = np.zeros((len(vertices), len(vertices)))
    local = np.einsum("f,fid,fjd->fij", areas, hat, hat)
    for i in range(3):
        for j in range(3):
            np.add.at(stiffness, (faces[:, i], faces[:, j]), local[:, i, j])
    assert np.allclose(stiffness, cotan_stiffness(vertices, faces).toarray(), atol=1e-10)
    # the gradient of u(x) = a·x on a face is a projected onto the face's plane
    a = np.array([0.3, -1.2, 0.7])
    grad = np.einsum("fi,fid->fd", (vertices @ a)[faces], hat)
    p = vertices[faces]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    assert np.allclose(grad, a - (normal @ a)[:, None] * normal, atol=1e-9)


def test_deformation_gradients_and_their_polar_parts(capsule):
    vertices, faces = capsule
    rng = np.random.default_rng(0)
    linear = np.array([[1.3, 0.2, 0.0], [-0.1, 0.8, 0.3], [0.2, 0.1, 1.1]])
    image = vertices @ linear.T + rng.normal(scale=0.01, size=vertices.shape)
    gradients = deformation_gradients(vertices, image, faces)
    p, q = vertices[faces], image[faces]
    for k in (1, 2):  # J maps each source edge onto the image's edge
        assert np.allclose(np.einsum("fij,fj->fi", gradients, p[:, k] - p[:, 0]), q[:, k] - q[:, 0], atol=1e-12)
    rotations, axes, stretches = polar_parts(gradients)
    assert np.allclose(np.einsum("fij,fkj->fik", rotations, rotations), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(rotations), 1.0)
    assert np.all(stretches > 0)
    stretch = np.einsum("fik,fk,fjk->fij", axes, stretches, axes)
    assert np.allclose(rotations @ stretch, gradients, atol=1e-12)


def test_unwrapped_rotation_vectors_give_the_same_rotations(capsule):
    vertices, faces = capsule
    rng = np.random.default_rng(1)
    rotations = Rotation.random(len(faces), random_state=rng).as_matrix()
    vectors = unwrapped_rotation_vectors(rotations, faces, np.ones(len(faces)))
    assert np.allclose(Rotation.from_rotvec(vectors).as_matrix(), rotations, atol=1e-9)


@pytest.mark.parametrize("degrees", [40.0, 150.0, 179.0])
def test_a_rigid_motion_is_interpolated_as_the_same_motion_in_part(capsule, degrees):
    vertices, faces = capsule
    axis = np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
    turn = Rotation.from_rotvec(np.deg2rad(degrees) * axis)
    centre = area_centroid(vertices, faces)
    shift = np.array([3.0, -1.0, 2.0])
    image = turn.apply(vertices - centre) + centre + shift
    sequence = rigid_interpolation(vertices, faces, image)
    for t in (0.0, 0.3, 0.5, 1.0, 1.4):
        part = Rotation.from_rotvec(t * np.deg2rad(degrees) * axis)
        expected = part.apply(vertices - centre) + centre + t * shift
        assert np.allclose(sequence.positions(t), expected, atol=1e-9), t


def test_a_twist_of_three_quarter_turns_turns_continuously():
    """A bar twisted about its axis by 270° at its far end: half way, the end has turned by 135°. A rotation
    vector taken as given (|θ| ≤ 180°) would turn the last third of the bar back by −45° instead."""
    bar = trimesh.creation.cylinder(radius=0.1, height=2.0, sections=24)
    bar = bar.subdivide_to_size(0.05)
    vertices, faces = np.asarray(bar.vertices), np.asarray(bar.faces)
    along = (vertices[:, 2] + 1.0) / 2.0  # 0 .. 1 along the bar

    def twisted(fraction):
        angle = np.deg2rad(270.0) * fraction * along
        c, s = np.cos(angle), np.sin(angle)
        return np.stack([c * vertices[:, 0] - s * vertices[:, 1], s * vertices[:, 0] + c * vertices[:, 1],
                         vertices[:, 2]], axis=1)

    mid = rigid_interpolation(vertices, faces, twisted(1.0)).positions(0.5)
    end = (along > 0.999) & (np.hypot(vertices[:, 0], vertices[:, 1]) > 0.05)  # the cap's rim
    turned = np.rad2deg(np.arctan2(mid[end, 1], mid[end, 0]) - np.arctan2(vertices[end, 1], vertices[end, 0]))
    turned = (turned + 180.0) % 360.0 - 180.0
    assert np.all(np.abs(turned - 135.0) < 5.0), turned
    assert np.abs(mid - twisted(0.5)).max() < 0.02  # close to the half twist everywhere (radius 0.1)


def test_the_ends_are_exact_for_any_map(wolf_pair):
    wolf0, wolf1 = wolf_pair
    rng = np.random.default_rng(2)
    partners = np.arange(wolf0.n_vertices)
    wrong = rng.choice(wolf0.n_vertices, size=wolf0.n_vertices // 20, replace=False)
    partners[wrong] = rng.integers(0, wolf1.n_vertices, size=wrong.size)  # 5 % sent anywhere
    image = wolf1.vertices[partners]
    for resolution in (0.0, float(np.mean(wolf1.edge_lengths))):
        sequence = rigid_interpolation(wolf0.vertices, wolf0.faces, image, resolution=resolution)
        assert np.allclose(sequence.positions(0.0), wolf0.vertices, atol=1e-9)
        assert np.allclose(sequence.positions(1.0), image, atol=1e-9)


def test_a_vertex_map_onto_another_mesh_keeps_the_volume(wolf_pair):
    """wolf0's vertices snapped to the nearest vertices of a 2,000-vertex remeshing of wolf1 (the best vertex map
    a method could give there). Half way, the as-rigid-as-possible shape keeps the volume; vertex interpolation
    loses 15 %, and the same interpolation without the diffusion over the target's edge length a third."""
    from corrlib.geometry.remeshing import remeshed

    wolf0, wolf1 = wolf_pair
    other = remeshed(wolf1, 2000).mesh
    image = other.vertices[cKDTree(other.vertices).query(wolf1.vertices)[1]]
    faces = wolf0.faces
    reference = 0.5 * (signed_volume(wolf0.vertices, faces) + signed_volume(image, faces))

    def mid_volume(resolution):
        positions = rigid_interpolation(wolf0.vertices, faces, image, resolution=resolution).positions(0.5)
        return signed_volume(positions, faces) / reference

    assert abs(mid_volume(float(np.mean(other.edge_lengths))) - 1.0) < 0.02
    assert mid_volume(0.0) < 0.9
    assert signed_volume(0.5 * (wolf0.vertices + image), faces) / reference < 0.9


def test_separate_parts_and_loose_vertices():
    """Two boxes turned about their own centres by different angles, and a vertex in no face: each box turns
    rigidly, and the loose vertex moves on a straight line."""
    box = trimesh.creation.box()
    b_vertices, b_faces = np.asarray(box.vertices), np.asarray(box.faces)
    vertices = np.vstack([b_vertices, b_vertices + [5.0, 0.0, 0.0], [[9.0, 9.0, 9.0]]])
    faces = np.vstack([b_faces, b_faces + len(b_vertices)])
    turns = [Rotation.from_rotvec([0.0, 0.0, np.deg2rad(90.0)]), Rotation.from_rotvec([np.deg2rad(60.0), 0.0, 0.0])]
    image = vertices.copy()
    halves = [slice(0, 8), slice(8, 16)]
    for part, turn in zip(halves, turns):
        centre = vertices[part].mean(axis=0)
        image[part] = turn.apply(vertices[part] - centre) + centre + [0.0, 1.0, 0.0]
    image[16] = [9.0, 9.0, 11.0]
    mid = rigid_interpolation(vertices, faces, image).positions(0.5)
    for part, turn in zip(halves, turns):
        centre = vertices[part].mean(axis=0)
        half_turn = Rotation.from_rotvec(0.5 * turn.as_rotvec())
        assert np.allclose(mid[part], half_turn.apply(vertices[part] - centre) + centre + [0.0, 0.5, 0.0],
                           atol=1e-9)
    assert np.allclose(mid[16], [9.0, 9.0, 10.0])


def test_bad_input_is_named(capsule):
    vertices, faces = capsule
    with pytest.raises(InputError, match=r"\(n, 3\)"):
        rigid_interpolation(vertices, faces, vertices[:-1])
    with pytest.raises(InputError, match="finite"):
        rigid_interpolation(vertices, faces, np.where(np.arange(len(vertices))[:, None] == 3, np.nan, vertices))
    with pytest.raises(InputError, match="faces"):
        rigid_interpolation(vertices, faces[:, :2], vertices)
    with pytest.raises(InputError, match="finite"):
        rigid_interpolation(vertices, faces, vertices).positions(float("inf"))


# ----------------------------------------------------------------------------- the sequences of corrlib.morph


def test_a_map_without_a_deformation_is_interpolated_as_rigidly_as_possible(wolf_pair):
    from corrlib.methods.base import MatchResult
    from corrlib.morph import (LINEAR_DESCRIPTION, RIGID_DESCRIPTION, describe_sequence, frame_positions,
                               sequence_positions)

    wolf0, wolf1 = wolf_pair
    ident = np.arange(wolf0.n_vertices)
    result = MatchResult("descriptor-nn", ident, ident)
    assert describe_sequence(result) == RIGID_DESCRIPTION
    assert describe_sequence(result, "linear") == LINEAR_DESCRIPTION
    mid = sequence_positions(result, wolf0, wolf1)(0.5)
    source_edges, target_edges = edge_lengths(wolf0.vertices, wolf0.faces), edge_lengths(wolf1.vertices, wolf0.faces)
    rigid_change = np.abs(edge_lengths(mid, wolf0.faces) / (0.5 * (source_edges + target_edges)) - 1).mean()
    linear_mid = sequence_positions(result, wolf0, wolf1, interpolation="linear")(0.5)
    assert np.allclose(linear_mid, 0.5 * (wolf0.vertices + wolf1.vertices))
    linear_change = np.abs(edge_lengths(linear_mid, wolf0.faces) / (0.5 * (source_edges + target_edges)) - 1).mean()
    assert rigid_change < 0.01 < 0.05 < linear_change  # measured 0.001 against 0.085
    first, last = frame_positions(result, wolf0, wolf1, [0.0, 1.0])
    assert np.allclose(first, wolf0.vertices, atol=1e-9) and np.allclose(last, wolf1.vertices, atol=1e-9)
    with pytest.raises(InputError, match="unknown interpolation"):
        frame_positions(result, wolf0, wolf1, [0.5], interpolation="cubic")


def test_unmatched_vertices_follow_the_matched_ones_round_them(wolf_pair):
    """A partial map (-1 rows) left its unmatched vertices at the source position, so an unmatched tail stayed
    behind and the faces between stretched over the whole motion; they now move by the harmonic extension of
    the matched displacements: a translation exactly, the wolves' other pose to a fraction of an edge."""
    from corrlib.methods.base import MatchResult
    from corrlib.morph import frame_positions, map_image

    wolf0, wolf1 = wolf_pair
    ident = np.arange(wolf0.n_vertices)
    tail = wolf0.vertices[:, 0] > np.percentile(wolf0.vertices[:, 0], 90)  # one end of the body, 435 vertices
    partial = np.where(tail, -1, ident)
    shifted = wolf0.vertices + [30.0, -12.0, 7.0]
    assert np.allclose(map_image(wolf0, shifted, partial), shifted, atol=1e-9)
    image = map_image(wolf0, wolf1.vertices, partial)
    assert np.array_equal(image[~tail], wolf1.vertices[~tail])
    error = np.linalg.norm(image[tail] - wolf1.vertices[tail], axis=1).mean()
    stayed = np.linalg.norm(wolf0.vertices[tail] - wolf1.vertices[tail], axis=1).mean()
    edge = float(np.mean(wolf0.edge_lengths))
    assert error < 0.5 * edge < 10 * edge < stayed  # measured 0.45 against 37.5 (edge 2.38)
    for interpolation in ("linear", "rigid"):
        last = frame_positions(MatchResult("descriptor-nn", partial, None), wolf0, wolf1, [0.5, 1.0],
                               interpolation=interpolation)
        assert np.allclose(last[1], image, atol=1e-6) and np.all(np.isfinite(last[0]))
    nothing = map_image(wolf0, wolf1.vertices, np.full(wolf0.n_vertices, -1))
    assert np.array_equal(nothing, wolf0.vertices)  # no matched vertex: nothing to follow


def test_harmonic_extension_reproduces_linear_functions_on_a_flat_mesh():
    """On a flat mesh a linear function is harmonic (the cotangent Laplacian of a coordinate is the mean
    curvature normal, zero in the plane): known on the boundary, it is recovered inside to rounding. A part with
    no known vertex gets zero; vector values are extended column by column."""
    from conftest import grid_mesh

    uv, faces = grid_mesh(12, 9)
    vertices = np.column_stack([uv * [1.0, 0.7], np.zeros(len(uv))])
    n = len(vertices)
    second = faces + n  # a second, separate copy of the grid without any known vertex
    vertices2 = np.vstack([vertices, vertices + [5.0, 0.0, 0.0]])
    faces2 = np.vstack([faces, second])
    linear = np.column_stack([vertices2 @ [0.3, -1.2, 0.0] + 2.0, vertices2 @ [-0.5, 0.4, 0.0]])
    edges_of_boundary = np.flatnonzero((uv.min(axis=1) <= 1e-12) | (uv.max(axis=1) >= uv.max() - 1e-12))
    known = np.zeros(2 * n, dtype=bool)
    known[edges_of_boundary] = True
    out = harmonic_extension(vertices2, faces2, np.where(known[:, None], linear, np.nan), known)
    assert np.allclose(out[:n], linear[:n], atol=1e-10)
    assert np.array_equal(out[n:], np.zeros((n, 2)))
    assert np.array_equal(harmonic_extension(vertices, faces, linear[:n, 0], np.ones(n, bool)), linear[:n, 0])
    gradient, areas = gradient_operator(vertices, faces)
    stiffness = gradient.T @ np.diag(np.repeat(areas, 3)) @ gradient
    assert np.allclose(stiffness, cotan_stiffness(vertices, faces).toarray())


def test_cli_morph_through_a_map(tmp_path, capsys):
    from _data import TOSCA
    from corrlib.cli import main
    from corrlib.io import load_mesh
    from corrlib.methods import all_methods

    out = tmp_path / "frames"
    argv = ["morph", str(TOSCA / "wolf0.off"), str(TOSCA / "wolf1.off"), "--method", "descriptor-nn", "--frames", "3",
            "-o", str(out)]
    assert main(argv) == 0
    said = capsys.readouterr().out
    assert "as-rigid-as-possible" in said
    folds = re.search(r"last frame \(t = 1, on wolf1.off's surface\): ([\d.]+) % of the faces turned over where the "
                      r"map crosses itself", said)  # descriptor-nn's map is far from one-to-one
    assert folds and float(folds.group(1)) > 0, said
    assert load_mesh(out / "frame_000.obj").n_vertices == load_mesh(TOSCA / "wolf0.off").n_vertices
    assert main(argv[:-2] + ["--interpolation", "linear", "-o", str(tmp_path / "linear")]) == 0
    assert "linear vertex interpolation" in capsys.readouterr().out
    assert main(argv[:-2] + ["--interpolation", "cubic", "-o", str(tmp_path / "never")]) == 2
    assert "--interpolation must be one of auto, flow, rigid, linear, got 'cubic'" in capsys.readouterr().err
    assert not (tmp_path / "never").exists()  # refused before any work
    assert main(argv[:-2] + ["--interpolation", "flow", "-o", str(tmp_path / "never")]) == 2
    assert ("--interpolation flow follows a method's flow (a deformation, as divergence-free fits), and --method "
            "descriptor-nn has none" in capsys.readouterr().err)
    assert not (tmp_path / "never").exists()
    # the registry says which methods fit a flow (the check above asks it): divergence-free alone
    assert [spec.name for spec in all_methods() if spec.deforms] == ["divergence-free"]


def test_the_folded_share_of_a_last_frame(wolf_pair):
    """``folded_share`` on the wolves (one connectivity): the identity's last frame, wolf1 itself, folds nowhere;
    wolf1 with every face turned over folds everywhere, and so does every vertex sent to one point (no area);
    a hundred turned faces are counted, and left out once a corner of each is unmatched; a map with none
    matched has nothing to fold."""
    from corrlib.morph import folded_share

    wolf0, wolf1 = wolf_pair
    identity = np.arange(wolf0.n_vertices)
    assert folded_share(wolf1.vertices, wolf0.faces, wolf1, identity) == 0.0
    assert folded_share(wolf1.vertices, wolf0.faces[:, ::-1], wolf1, identity) == 1.0
    assert folded_share(np.zeros_like(wolf1.vertices), wolf0.faces, wolf1, identity) == 1.0
    turned = wolf0.faces.copy()
    turned[:100] = turned[:100, ::-1]  # a hundred faces turned over
    assert folded_share(wolf1.vertices, turned, wolf1, identity) == pytest.approx(100 / wolf0.n_faces)
    partial = identity.copy()
    partial[np.unique(turned[:100])] = -1  # their corners unmatched: not counted
    assert folded_share(wolf1.vertices, turned, wolf1, partial) == 0.0
    assert folded_share(wolf1.vertices, wolf0.faces, wolf1, np.full_like(identity, -1)) == 0.0


def test_a_sequence_from_python_through_a_bare_map(tmp_path):
    """The library's sequence functions take a map as ``corr morph --map`` does (a result of its own): the wolves'
    identity goes from wolf0 to wolf1 exactly; the frames are written only where every one is a mesh, and a
    map of the wrong length, not whole numbers, a contour for a mesh or the flow of a map are named."""
    from _data import TOSCA
    from corrlib.errors import InputError
    from corrlib.io import load_contour, load_mesh
    from corrlib.morph import export_sequence, frame_positions, sequence_positions
    from corrlib.resources import resource

    wolf0, wolf1 = load_mesh(TOSCA / "wolf0.off"), load_mesh(TOSCA / "wolf1.off")
    identity = np.arange(wolf0.n_vertices)
    first, last = frame_positions(identity.astype(float), wolf0, wolf1, [0.0, 1.0])  # a map read by np.loadtxt
    assert np.allclose(first, wolf0.vertices, atol=1e-9) and np.allclose(last, wolf1.vertices, atol=1e-9)
    assert np.allclose(sequence_positions(identity, wolf0, wolf1, interpolation="linear")(0.5),
                       (wolf0.vertices + wolf1.vertices) / 2)
    drawn = load_contour(resource("data/silhouettes/drawn/wolf.txt"))
    for args, message in [((identity[:9], wolf0, wolf1), r"the map must hold one target vertex per source vertex, "
                                                          r"shape \(4344,\); got shape \(9,\)"),
                          ((identity + 0.5, wolf0, wolf1), "the map must hold integer vertex indices; entry 0 is 0.5"),
                          ((identity, drawn, wolf1), "the source must be a TriMesh, got Contour2D")]:
        with pytest.raises(InputError, match=message):
            frame_positions(*args, [0.0])
    with pytest.raises(InputError, match="has no flow .* use rigid or linear"):
        frame_positions(identity, wolf0, wolf1, [0.0], interpolation="flow")
    for frames, faces, message in [([first, last[:9]], wolf0.faces, r"frame 1 must hold positions of shape"),
                                   ([first, last * np.nan], wolf0.faces, "frame 1 holds NaN or infinite positions"),
                                   ([first, last], wolf0.faces + wolf0.n_vertices, "face")]:
        with pytest.raises(InputError, match=message):
            export_sequence(tmp_path / "frames", frames, faces, [0.0, 1.0])
        assert not (tmp_path / "frames").exists()  # refused before the folder is made
    written = export_sequence(tmp_path / "frames", [first, last], wolf0.faces, [0.0, 1.0], fmt="off")
    assert np.allclose(load_mesh(written["frames"][1]).vertices, wolf1.vertices, atol=1e-6)


def test_cli_morph_through_a_given_map(tmp_path, capsys):
    """``corr morph --map``: no method runs; the frames go from the source to the map's image."""
    from _data import TOSCA
    from corrlib.cli import main
    from corrlib.io import load_mesh, save_map

    wolf0, wolf1 = load_mesh(TOSCA / "wolf0.off"), load_mesh(TOSCA / "wolf1.off")
    identity = save_map(tmp_path / "identity.txt", np.arange(wolf0.n_vertices))  # the wolves share connectivity
    out = tmp_path / "frames"
    argv = ["morph", str(TOSCA / "wolf0.off"), str(TOSCA / "wolf1.off"), "--map", str(identity), "--frames", "3",
            "--t-max", "1", "--format", "off"]
    assert main(argv + ["-o", str(out)]) == 0
    said = capsys.readouterr().out
    assert "as-rigid-as-possible" in said and "largest relative change" in said
    assert "last frame (t = 1, on wolf1.off's surface): 0.0 % of the faces turned over\n" in said
    assert np.allclose(load_mesh(out / "frame_002.off").vertices, wolf1.vertices, atol=1e-4)
    assert not list(out.glob("result*"))  # the map is the user's file: nothing to write back
    for extra, message in [(["--method", "kernel-matching"], "give --map or --method, not both"),
                           (["--param", "k=3"], "give --map or --param, not both")]:
        assert main(argv + extra + ["-o", str(tmp_path / "never")]) == 2
        assert message in capsys.readouterr().err
    short = save_map(tmp_path / "short.txt", np.arange(10))
    assert main(argv[:4] + [str(short), "-o", str(tmp_path / "never")]) == 2
    assert "short.txt: map has 10 entries but the source has 4344 vertices" in capsys.readouterr().err
    assert not (tmp_path / "never").exists()


def test_vertex_order_and_mirror_images_do_not_change_the_sequence(wolf_pair):
    """The sequence of wolf0 → wolf1 (a map with 5 % of its partners wrong, diffused over an edge length) is
    the same, vertex for vertex, when both meshes' vertices are shuffled or both are mirrored."""
    wolf0, wolf1 = wolf_pair
    rng = np.random.default_rng(4)
    partners = np.arange(wolf0.n_vertices)
    wrong = rng.choice(wolf0.n_vertices, size=wolf0.n_vertices // 20, replace=False)
    partners[wrong] = rng.integers(0, wolf1.n_vertices, size=wrong.size)
    image, faces = wolf1.vertices[partners], wolf0.faces
    resolution = float(np.mean(wolf1.edge_lengths))
    mid = rigid_interpolation(wolf0.vertices, faces, image, resolution=resolution).positions(0.5)
    order = rng.permutation(wolf0.n_vertices)
    inverse = np.argsort(order)
    shuffled = rigid_interpolation(wolf0.vertices[order], inverse[faces], image[order], resolution=resolution)
    assert np.allclose(shuffled.positions(0.5)[inverse], mid, atol=1e-8)
    flip = np.array([-1.0, 1.0, 1.0])
    mirrored = rigid_interpolation(wolf0.vertices * flip, faces[:, ::-1], image * flip, resolution=resolution)
    assert np.allclose(mirrored.positions(0.5) * flip, mid, atol=1e-8)
