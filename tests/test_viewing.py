"""Up axis, view frames, fitted cameras and camera files (corrlib.viewing, no Qt)."""

import json

import numpy as np
import pytest

from corrlib.errors import FileFormatError, InputError, ParameterError
from corrlib.io import load_mesh
from corrlib.plotting import view_axes
from corrlib.resources import resource
from corrlib.viewing import Camera, axis_vector, detect_up, fitted_camera, support_shares, view_frame
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
