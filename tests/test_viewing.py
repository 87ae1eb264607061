"""Up axis, view frames, fitted cameras and camera files (corrlib.viewing, no Qt)."""

import json

import numpy as np
import pytest

from corrlib.errors import FileFormatError, InputError, ParameterError
from corrlib.io import load_mesh
from corrlib.plotting import view_axes
from corrlib.resources import resource
from corrlib.viewing import (Camera, ViewFrame, axis_vector, detect_up, fitted_camera, outline_fit, outline_frame,
                             support_shares, upright_frames, view_frame)
from tests._data import SUMNER, TOSCA

#: the up axis of every bundled shape, by its dataset's convention
KNOWN_UP = {TOSCA / "cat0.off": "+z", TOSCA / "cat1.off": "+z", TOSCA / "wolf0.off": "+z",
            TOSCA / "wolf1.off": "+z", SUMNER / "cat-00.off": "+y", SUMNER / "lion-00.off": "+y"}


def test_the_up_axis_of_every_bundled_shape():
    known = dict(KNOWN_UP)
    known.update({resource(f"people/human{i}.off"): "+y" for i in range(4)})
    for path, up in known.items():
        assert detect_up(load_mesh(path).vertices) == up, path


@pytest.mark.parametrize("perm, signs", [((0, 2, 1), (1, 1, 1)), ((2, 0, 1), (1, 1, -1)), ((1, 2, 0), (-1, 1, 1))])
def test_the_up_axis_follows_the_file_axes(perm, signs):
    """Relabelling and flipping the coordinate axes moves the detected up axis with them; so does any
    scale and translation (none changes which side the shape stands on)."""
    wolf = load_mesh(TOSCA / "wolf0.off").vertices
    moved = wolf[:, perm] * np.array(signs) * 3.7 + 100.0
    up = axis_vector(detect_up(wolf))
    expected = (up[list(perm)] * np.array(signs))
    assert np.array_equal(axis_vector(detect_up(moved)), expected)


@pytest.mark.parametrize("perm, signs", [((0, 1, 2), (1, 1, 1)), ((0, 2, 1), (1, 1, 1)), ((2, 0, 1), (-1, 1, 1))])
def test_a_flat_sketch_stands_on_its_feet_and_faces_the_camera(perm, signs):
    """A triangulated 2D sketch (a person drawn in the xy plane, feet down) lies in a coordinate plane: its
    up axis is the drawing's up, in its plane, whichever axes the file uses, and its front view looks at the
    drawing face-on (before, every flat shape had all shares 0 and was stood on +x, drawn lying on its side)."""
    for name in ("human_sketch_a", "human_sketch_b"):
        sketch = load_mesh(resource(f"data/sketch2d/{name}.off")).vertices
        moved = sketch[:, perm] * np.array(signs) * 0.3 + 5.0
        drawn_up = np.array([0.0, 1.0, 0.0])[list(perm)] * np.array(signs)
        assert np.array_equal(axis_vector(detect_up(moved)), drawn_up), name
        normal = np.zeros(3)
        normal[int(np.argmin(np.ptp(moved, axis=0)))] = 1.0
        assert abs(view_frame(moved).toward @ normal) == pytest.approx(1.0)


def test_support_shares_prefer_feet_to_a_nose():
    shares = support_shares(load_mesh(TOSCA / "cat0.off").vertices)
    assert shares["+z"] > 3 * max(v for k, v in shares.items() if k != "+z")


def test_view_frames_are_rotations_with_the_asked_up():
    cat = load_mesh(TOSCA / "cat0.off").vertices
    for up in ("auto", "+x", "-y", "+z"):
        frame = view_frame(cat, up)
        assert np.allclose(frame.matrix @ frame.matrix.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(frame.matrix) == pytest.approx(1.0)
        if up != "auto":
            assert np.array_equal(frame.up, axis_vector(up))
    # the front view looks at the broad side: the cat's head-to-tail axis runs across the screen
    frame = view_frame(cat)
    extents = np.ptp(cat @ frame.matrix.T, axis=0)
    assert extents[0] > extents[2]  # wider across the screen than deep
    with pytest.raises(ParameterError, match="up axis"):
        view_frame(cat, "up")
    # the pictures use the same frame: x right, y away from the viewer, z up
    assert np.allclose(view_axes(cat), np.stack([frame.right, -frame.toward, frame.up]))


@pytest.mark.parametrize("view", ["front", "side", "top"])
@pytest.mark.parametrize("aspect", [0.5, 1.0, 2.0])
def test_a_fitted_camera_sees_every_point_and_fills_the_view(view, aspect):
    """Pinhole projection of every vertex: inside the view angle, and the widest one at 1/margin of it."""
    points = load_mesh(TOSCA / "wolf0.off").vertices
    frame = view_frame(points)
    camera = fitted_camera(points, frame, view, aspect=aspect, view_angle=30.0, margin=1.05)
    position, focal, up = (np.array(x) for x in (camera.position, camera.focal_point, camera.view_up))
    forward = (focal - position) / np.linalg.norm(focal - position)
    right = np.cross(forward, up)
    rel = points - position
    depth = rel @ forward
    assert np.all(depth > 0)
    tan_half = np.tan(np.radians(15.0))
    x = np.abs(rel @ right) / depth / (tan_half * aspect)
    y = np.abs(rel @ up) / depth / tan_half
    fill = max(x.max(), y.max())
    assert fill <= 1.0
    assert fill == pytest.approx(1 / 1.05)  # the widest vertex at the margin: the shape fills its viewport
    toward, screen_up = frame.direction(view)
    assert np.allclose(-forward, toward) and np.allclose(up, screen_up)


def test_camera_files_round_trip_and_bad_files_are_named(tmp_path):
    camera = Camera((1.0, 2.0, 3.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 25.0)
    path = camera.save(tmp_path / "view.json")
    assert Camera.load(path) == camera
    assert json.loads(path.read_text())["view_angle"] == 25.0
    cases = {"text.json": "not json", "short.json": json.dumps({"position": [1, 2], "focal_point": [0, 0, 0],
                                                                "view_up": [0, 1, 0]}),
             "missing.json": json.dumps({"position": [1, 2, 3]}),
             "nan.json": '{"position": [1, 2, NaN], "focal_point": [0, 0, 0], "view_up": [0, 1, 0]}',
             "same.json": json.dumps({"position": [0, 0, 0], "focal_point": [0, 0, 0], "view_up": [0, 1, 0]}),
             "angle.json": json.dumps({"position": [1, 0, 0], "focal_point": [0, 0, 0], "view_up": [0, 1, 0],
                                       "view_angle": 400})}
    for name, text in cases.items():
        (tmp_path / name).write_text(text)
        with pytest.raises(FileFormatError, match=name):
            Camera.load(tmp_path / name)
    with pytest.raises(FileFormatError):
        Camera.load(tmp_path / "absent.json")
    with pytest.raises(InputError):
        camera.save(tmp_path)  # a folder, not a file


#: an L-shaped closed curve in a plane (no symmetry: its mirror image is no turn of it)
L_SHAPE = np.array([[0, 0], [3, 0], [3, 1], [1, 1], [1, 4], [0, 4]], dtype=np.float64)


def _seen_from(frame: ViewFrame, curve: np.ndarray, turn: float = 0.0, scale: float = 1.0) -> np.ndarray:
    """(p, 2): the outline a drawing of ``curve`` seen from the front of ``frame`` would give, turned and scaled."""
    screen = np.column_stack([curve @ frame.right, curve @ frame.up])
    rotation = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    return scale * screen @ rotation.T + 5.0


def test_upright_frames_are_rotations_that_keep_the_shape_upright():
    frame = view_frame(load_mesh(TOSCA / "wolf0.off").vertices)
    for name, candidate in upright_frames(frame).items():
        assert np.allclose(candidate.matrix @ candidate.matrix.T, np.eye(3)), name
        assert np.isclose(np.linalg.det(candidate.matrix), 1.0), name
        if name != "top":
            assert np.allclose(candidate.up, frame.up), name  # the shape's up is the screen's up
    assert np.allclose(upright_frames(frame)["top"].toward, frame.up)  # seen from above, never from below


@pytest.mark.parametrize("view", ["front", "back", "side", "other side", "top"])
def test_the_view_a_curve_was_drawn_from_is_found(view):
    """An L drawn in the plane of one upright view, seen from that view (turned by 30° and scaled, as a
    sketch is drawn), fits it exactly and that view is chosen; its mirror image, seen from the opposite view,
    does not fit the same view (a similarity has no reflection)."""
    frame = view_frame(load_mesh(TOSCA / "wolf0.off").vertices)
    frames = upright_frames(frame)
    chosen = frames[view]
    curve = np.column_stack([L_SHAPE, np.full(len(L_SHAPE), 0.3)]) @ chosen.matrix  # in chosen's screen plane
    outline = _seen_from(chosen, curve, turn=np.radians(30), scale=2.5)
    assert outline_fit(curve, outline, chosen) == pytest.approx(1.0)
    assert np.allclose(outline_frame(curve, outline, frame).matrix, chosen.matrix)
    mirrored = outline * np.array([-1.0, 1.0])
    assert outline_fit(curve, mirrored, chosen) < 0.5
    if view != "top":
        opposite = {"front": "back", "back": "front", "side": "other side", "other side": "side"}[view]
        assert np.allclose(outline_frame(curve, mirrored, frame).matrix, frames[opposite].matrix)


def test_outline_fit_of_a_curve_seen_edge_on_and_bad_shapes():
    frame = view_frame(load_mesh(TOSCA / "wolf0.off").vertices)
    curve = np.column_stack([L_SHAPE, np.zeros(len(L_SHAPE))]) @ frame.matrix  # in the front plane
    seen_edge_on = upright_frames(frame)["top"]
    assert outline_fit(curve, _seen_from(frame, curve), seen_edge_on) < 0.9
    assert outline_fit(np.zeros((6, 3)), _seen_from(frame, curve), frame) == 0.0  # a curve at one point
    with pytest.raises(ParameterError, match="the same p"):
        outline_fit(curve, L_SHAPE[:5], frame)


@pytest.mark.parametrize("view", ["front", "side", "top"])
@pytest.mark.parametrize("aspect", [0.5, 2.0])
def test_a_fitted_camera_keeps_the_top_free_for_a_caption(view, aspect):
    """With ``top=0.2`` of the viewport's height kept free, every vertex is below that band (normalised screen
    height 1 − 2 · 0.2) and in view, each within the margin; and the nearest to an edge is at it: the shape fills
    what is left."""
    points = load_mesh(TOSCA / "wolf0.off").vertices
    frame = view_frame(points)
    camera = fitted_camera(points, frame, view, aspect=aspect, view_angle=30.0, margin=1.05, top=0.2)
    position, focal, up = (np.array(x) for x in (camera.position, camera.focal_point, camera.view_up))
    forward = (focal - position) / np.linalg.norm(focal - position)
    right = np.cross(forward, up)
    rel = points - position
    depth = rel @ forward
    tan_half = np.tan(np.radians(15.0))
    x = np.abs(rel @ right) / depth / (tan_half * aspect)
    y = (rel @ up) / depth / tan_half
    assert np.all(depth > 0)
    # each vertex's room to the edges, in units of its margin: all at least 1, the tightest exactly 1
    room = np.min([1.0 / (1.05 * x), (1.0 - 2 * 0.2) / (1.05 * np.maximum(y, 1e-12)),
                   1.0 / (1.05 * np.maximum(-y, 1e-12))], axis=0)
    assert room.min() == pytest.approx(1.0)
    assert y.max() <= 1.0 - 2 * 0.2 and y.min() >= -1.0
    with pytest.raises(ParameterError, match="top"):
        fitted_camera(points, frame, view, top=1.0)


def test_contours_side_by_side_face_one_way_where_their_partners_do():
    """B drawn mirrored exactly where its matched points run the other way along the horizontal: a contour
    against its own mirror image (partners by index) is drawn unmirrored beside it, so every line between
    partners has the same length; the same contour against itself is not mirrored; with no map B is as drawn.
    B stands to A's right at A's height either way."""
    from corrlib.viewing import contours_side_by_side

    t = np.linspace(0, 2 * np.pi, 80, endpoint=False)
    a = np.column_stack([np.cos(t) + 0.4 * np.cos(2 * t), 0.6 * np.sin(t)])  # a lopsided, left-right asymmetric loop
    partners = np.arange(80)
    for b, expected in ((a * [-2.0, 2.0] + 5.0, True), (a * 3.0, False)):
        shown_a, shown_b, mirrored = contours_side_by_side(a, b, partners)
        assert mirrored is expected
        lines = shown_b[partners] - shown_a
        assert np.allclose(lines, lines[0])  # parallel and equally long: no line crosses another
        assert shown_a[:, 0].max() < shown_b[:, 0].min() and np.ptp(shown_b[:, 1]) == pytest.approx(np.ptp(a[:, 1]))
    shown_a, shown_b, mirrored = contours_side_by_side(a, a * [-1.0, 1.0])
    assert not mirrored and np.allclose(shown_b - shown_b.mean(0), a * [-1.0, 1.0] - (a * [-1.0, 1.0]).mean(0))
    unmatched = np.full(80, -1)
    unmatched[:3] = [0, 1, 2]
    assert contours_side_by_side(a, a * [-1.0, 1.0], unmatched)[2] is True  # the matched points decide
    assert contours_side_by_side(a, a, np.full(80, -1))[2] is False
