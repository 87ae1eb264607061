"""How a shape is shown: its up axis, the front/side/top views and a camera as plain data (Qt- and VTK-free).

The studio's views, its retrieval thumbnails and the CLI's pictures all frame
a shape with the same rules, so a shape looks alike everywhere.

**Up axis.** Mesh files put "up" along one of their coordinate axes, by
convention of the dataset (TOSCA: +z, the Sumner meshes and most graphics
files: +y). The automatic choice is the side a standing shape rests on: for
each of the six directions ±x, ±y, ±z, the vertices within the lowest 3 % of
the shape's extent along it (its *bottom slab*) cover some share of the
shape's footprint (convex hulls of their projections onto the perpendicular
plane). Four paws or two feet spread over the footprint; a nose, a tail tip,
a head or a hand does not. The direction whose slab covers the largest share
is down. A flat shape (a triangulated 2D sketch in a coordinate plane) stands
on an edge: its footprint seen along an axis of its plane is a segment, and
the share is that of the segment's length; its up axis lies in its plane, so
its front view faces the drawing. A user can override it (``+x`` … ``-z``).

**Views.** With ``up`` fixed, the horizontal principal axes of the vertices
give the long and the short horizontal extent. ``front`` looks at the broad
side (along the short horizontal axis: an animal's flank, a person's front or
back), ``side`` at the narrow side (along the long horizontal axis), ``top``
down the up axis. The sign of a horizontal axis is arbitrary; it is fixed so
that its largest coordinate component is positive, which keeps the views of
one dataset alike.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from corrlib.errors import FileFormatError, ParameterError
from corrlib.shapes import PLANAR_TOLERANCE

#: the values of an up-axis setting
UP_AXES = ("auto", "+x", "-x", "+y", "-y", "+z", "-z")
#: the camera presets
VIEWS = ("front", "side", "top")
#: thickness of the bottom slab of the automatic up axis, a fraction of the extent
SUPPORT_SLAB = 0.03


def axis_vector(name: str) -> np.ndarray:
    """(3,) float unit vector of ``"+x"`` … ``"-z"``."""
    if name not in UP_AXES[1:]:
        raise ParameterError(f"up axis must be one of {', '.join(UP_AXES)}, got {name!r}")
    vector = np.zeros(3)
    vector["xyz".index(name[1])] = 1.0 if name[0] == "+" else -1.0
    return vector


def _hull_area(points_2d: np.ndarray) -> float:
    from scipy.spatial import ConvexHull, QhullError

    if points_2d.shape[0] < 3:
        return 0.0
    try:
        return float(ConvexHull(points_2d).volume)  # the "volume" of a 2D hull is its area
    except QhullError:  # collinear points
        return 0.0


def _hull_length(points_2d: np.ndarray, line: np.ndarray) -> float:
    """The length of the points' span along ``line`` (2,): the 1D hull of points of a flat shape seen edge-on."""
    return float(np.ptp(points_2d @ line)) if points_2d.shape[0] else 0.0


def support_shares(vertices: np.ndarray) -> dict[str, float]:
    """Share of the footprint covered by the bottom slab, for each of ``+x`` … ``-z`` as up (see the module)."""
    v = np.asarray(vertices, dtype=np.float64)
    v = v - v.mean(axis=0)
    extents = np.ptp(v, axis=0)
    flat_axis = int(np.argmin(extents))
    # flat as a planar sketch is (:func:`corrlib.shapes.plane_coordinates`), in a coordinate plane
    flat = extents[flat_axis] <= PLANAR_TOLERANCE * max(float(np.linalg.norm(extents)), np.finfo(float).tiny)
    shares = {}
    for name in UP_AXES[1:]:
        up = axis_vector(name)
        axis = int(np.argmax(np.abs(up)))
        others = [a for a in range(3) if a != axis]
        height = v @ up
        extent = float(np.ptp(height))
        slab = v[height <= height.min() + SUPPORT_SLAB * extent, :][:, others] if extent > 0 else v[:0, others]
        if flat and axis != flat_axis:  # a flat shape rests on an edge: its footprint is a segment
            line = np.array([float(a != flat_axis) for a in others])
            footprint, covered = _hull_length(v[:, others], line), _hull_length(slab, line)
        else:
            footprint, covered = _hull_area(v[:, others]), _hull_area(slab)
        shares[name] = covered / footprint if footprint > 0 and extent > 0 else 0.0
    return shares


def detect_up(vertices: np.ndarray) -> str:
    """The automatic up axis (``"+x"`` … ``"-z"``) of a shape (see the module docstring)."""
    shares = support_shares(vertices)
    return max(UP_AXES[1:], key=lambda name: shares[name])


@dataclass(frozen=True)
class ViewFrame:
    """Orthonormal frame of a shape's views (rows of :attr:`matrix`).

    Attributes
    ----------
    right : (3,) float
        Screen right in the front view (the long horizontal axis).
    up : (3,) float
    toward : (3,) float
        From the shape toward the camera of the front view.
    """

    right: np.ndarray
    up: np.ndarray
    toward: np.ndarray

    @property
    def matrix(self) -> np.ndarray:
        """(3, 3) rows right, up, toward (a proper rotation)."""
        return np.stack([self.right, self.up, self.toward])

    def direction(self, view: str) -> tuple[np.ndarray, np.ndarray]:
        """Unit vector from the shape toward the camera (3,) and the screen's up (3,) of a preset view."""
        if view == "front":
            return self.toward, self.up
        if view == "side":
            return self.right, self.up
        if view == "top":
            return self.up, -self.toward
        raise ParameterError(f"view must be one of {', '.join(VIEWS)}, got {view!r}")


def _signed(axis: np.ndarray) -> np.ndarray:
    return axis if axis[np.argmax(np.abs(axis))] > 0 else -axis


def view_frame(vertices: np.ndarray, up: str = "auto") -> ViewFrame:
    """The :class:`ViewFrame` of a shape with the given up-axis setting."""
    if up not in UP_AXES:
        raise ParameterError(f"up axis must be one of {', '.join(UP_AXES)}, got {up!r}")
    v = np.asarray(vertices, dtype=np.float64)
    up_vector = axis_vector(detect_up(v) if up == "auto" else up)
    centred = v - v.mean(axis=0)
    horizontal = centred - np.outer(centred @ up_vector, up_vector)
    _, _, vt = np.linalg.svd(horizontal, full_matrices=False)
    long_axis = vt[0] - (vt[0] @ up_vector) * up_vector
    long_axis = _signed(long_axis / max(np.linalg.norm(long_axis), 1e-300))
    toward = np.cross(long_axis, up_vector)  # right x up = toward the viewer (a right-handed screen)
    return ViewFrame(long_axis, up_vector, toward)


def upright_frames(frame: ViewFrame) -> dict[str, ViewFrame]:
    """The frames whose front views are the shape's upright views: the ``front`` preset and the ``back``, the
    ``side`` preset and the ``other side``, and the ``top`` preset (a view from below is no view a shape is
    drawn from). Each is a proper rotation (right × up = toward)."""
    right, up, toward = frame.right, frame.up, frame.toward
    return {"front": frame, "back": ViewFrame(-right, up, -toward), "side": ViewFrame(-toward, up, right),
            "other side": ViewFrame(toward, up, -right), "top": ViewFrame(right, -toward, up)}


def outline_fit(curve: np.ndarray, outline: np.ndarray, frame: ViewFrame) -> float:
    """How well a curve seen from the front of ``frame`` looks like the 2D outline matched to it, in [0, 1].

    The curve's orthographic projection onto the screen (right, up) is fitted to the outline by a similarity
    without reflection; in complex numbers ``a ≈ z b`` (outline ``a``, projection ``b``, both centred) the
    least-squares ``z = bᴴa / bᴴb`` leaves the relative residual ``1 − |bᴴa|² / (|a|² |b|²)`` (Umeyama 1991).
    Returns one minus that residual: 1 for a projection that is the outline turned and scaled, 0 for one
    uncorrelated with it (or a curve that projects to a point).

    Parameters
    ----------
    curve : (p, 3) float
        Points of the curve.
    outline : (p, 2) float
        The outline's point matched to each (x right, y up).
    frame : ViewFrame
    """
    curve = np.asarray(curve, dtype=np.float64)
    outline = np.asarray(outline, dtype=np.float64)
    if curve.ndim != 2 or curve.shape[1] != 3 or outline.shape != (curve.shape[0], 2):
        raise ParameterError(f"curve must be (p, 3) and outline (p, 2) with the same p, got {curve.shape} and "
                             f"{outline.shape}")
    a = outline[:, 0] + 1j * outline[:, 1]
    b = curve @ frame.right + 1j * (curve @ frame.up)
    a, b = a - a.mean(), b - b.mean()
    norms = float(np.vdot(a, a).real) * float(np.vdot(b, b).real)
    return 0.0 if norms <= 0.0 else float(abs(np.vdot(b, a)) ** 2 / norms)


def outline_frame(curve: np.ndarray, outline: np.ndarray, frame: ViewFrame) -> ViewFrame:
    """Of the shape's upright views (:func:`upright_frames`), the one from which a curve matched to a 2D outline
    looks most like it (:func:`outline_fit`).

    A curve matched to a silhouette lies along the shape's outline as seen from where the silhouette was drawn,
    so from that view the whole curve is in sight, on the shape's border; from another it can run behind the
    shape. Mirror views (front and back, the two sides) differ in the sign of the fit's turn, which a
    similarity without reflection tells apart.
    """
    frames = upright_frames(frame)
    return max(frames.values(), key=lambda candidate: outline_fit(curve, outline, candidate))


@dataclass
class Camera:
    """A camera as plain data (position, focal point, view up, view angle in degrees), saved as JSON.

    The format follows what viewers such as Polyscope write for a view: one
    JSON object with these four fields.
    """

    position: tuple[float, float, float]
    focal_point: tuple[float, float, float]
    view_up: tuple[float, float, float]
    view_angle: float = 30.0

    def save(self, path) -> Path:
        from corrlib.io import atomic_write, check_output_file

        path = check_output_file(path, "camera file")
        with atomic_write(path) as fh:
            json.dump({"corrlib_camera": 1, **asdict(self)}, fh, indent=2)
        return path

    @classmethod
    def load(cls, path) -> "Camera":
        from corrlib.io import read_text

        text = read_text(path, "camera file")
        try:
            data = json.loads(text)
            vectors = [tuple(float(x) for x in data[key]) for key in ("position", "focal_point", "view_up")]
            angle = float(data.get("view_angle", 30.0))
        except (ValueError, TypeError, KeyError) as exc:
            raise FileFormatError(f"{path}: not a camera file (expected a JSON object with position, focal_point "
                                  f"and view_up as 3 numbers each): {exc}") from None
        if any(len(vec) != 3 for vec in vectors) or not np.all(np.isfinite(np.concatenate(vectors + [[angle]]))):
            raise FileFormatError(f"{path}: position, focal_point and view_up must be 3 finite numbers each")
        if np.linalg.norm(np.subtract(vectors[0], vectors[1])) == 0 or np.linalg.norm(vectors[2]) == 0:
            raise FileFormatError(f"{path}: the camera sits on its focal point or has no up vector")
        if not 0.0 < angle < 180.0:
            raise FileFormatError(f"{path}: view_angle must be in (0, 180) degrees, got {angle}")
        return cls(*vectors, view_angle=angle)


def fitted_camera(vertices: np.ndarray, frame: ViewFrame, view: str = "front", aspect: float = 1.0,
                  view_angle: float = 30.0, margin: float = 1.05, top: float = 0.0) -> Camera:
    """The camera of a preset view that fits the shape tightly into a viewport of width/height ``aspect``.

    The distance is the smallest at which every vertex lies within the view
    angle shrunk by ``margin`` (each vertex's own depth counts, so the nearest
    wide part decides): the shape fills its viewport instead of its bounding
    sphere. ``top`` (a fraction ``t`` of the viewport's height, below 1) is
    kept free at the top for a caption: camera and focal point move up by
    ``s = t d tan(θ/2) / margin`` at the distance ``d``, and ``d`` is the
    smallest at which every vertex (screen height ``u``, depth ``d − z``) lies
    below the band, ``(u − s) margin ≤ (1 − 2t)(d − z) tan(θ/2)``, and above
    the bottom, ``(s − u) margin ≤ (d − z) tan(θ/2)``: both are linear in ``d``.
    """
    if aspect <= 0:
        raise ParameterError(f"aspect must be positive, got {aspect!r}")
    if not 0.0 <= top < 1.0:
        raise ParameterError(f"top must be in [0, 1), got {top!r}")
    v = np.asarray(vertices, dtype=np.float64)
    toward, screen_up = frame.direction(view)
    screen_right = np.cross(screen_up, toward)
    lo, hi = v.min(axis=0), v.max(axis=0)
    centre = (lo + hi) / 2
    rel = v - centre
    tan_half = np.tan(np.radians(view_angle) / 2)
    depth, height = rel @ toward, rel @ screen_up
    # vertex i is in view from distance d along `toward` if its extent times the margin is within d - depth_i
    across = depth + margin * np.abs(rel @ screen_right) / (aspect * tan_half)
    below_band = (margin * height + (1.0 - 2.0 * top) * depth * tan_half) / ((1.0 - top) * tan_half)
    above_bottom = (depth * tan_half - margin * height) / ((1.0 - top) * tan_half)
    distance = max(float(np.max(np.maximum(across, np.maximum(below_band, above_bottom)))), 1e-12)
    focal = centre + (top * distance * tan_half / margin) * screen_up
    return Camera(tuple(focal + distance * toward), tuple(focal), tuple(screen_up), view_angle)


def contours_side_by_side(points_a: np.ndarray, points_b: np.ndarray, map_xy: np.ndarray | None = None,
                          gap: float = 0.2) -> tuple[np.ndarray, np.ndarray, bool]:
    """Two contours placed for a picture of their correspondence: B scaled to A's height and put to A's right,
    ``gap`` times the wider width apart, both centred on one horizontal line.

    Given the correspondence, B is drawn mirrored left to right where that puts its points nearer their
    partners' horizontal places: of B as drawn and its mirror image, the one whose matched points' horizontal
    coordinates fit A's better by least squares with a shift, ``min Σ (x_a − s x_b − t)²`` over ``s = ±1``, i.e.
    the sign of their covariance. Two outlines facing opposite ways (a horse drawn looking right, a dog looking
    left) are then drawn facing one way, and the lines between partners do not cross the picture.

    Parameters
    ----------
    points_a : (m, 2) float
    points_b : (n, 2) float
    map_xy : (m,) int, optional
        The point of B matched to each point of A (negative: unmatched).

    Returns
    -------
    (m, 2) and (n, 2) float: the two contours as drawn; and whether B is drawn mirrored.
    """
    a = np.asarray(points_a, dtype=np.float64)
    b = np.asarray(points_b, dtype=np.float64)
    a = a - (a.min(0) + a.max(0)) / 2
    b = (b - (b.min(0) + b.max(0)) / 2) * (np.ptp(a[:, 1]) / max(np.ptp(b[:, 1]), 1e-300))
    mirrored = False
    if map_xy is not None:
        matched = np.asarray(map_xy) >= 0
        xa, xb = a[matched, 0], b[np.asarray(map_xy)[matched], 0]
        mirrored = bool(matched.sum() > 1 and np.dot(xa - xa.mean(), xb - xb.mean()) < 0)
    if mirrored:
        b = b * [-1.0, 1.0]
    width_a, width_b = np.ptp(a[:, 0]), np.ptp(b[:, 0])
    return a, b + [(width_a + width_b) / 2 + gap * max(width_a, width_b), 0.0], mirrored
