"""A fitted deformation: a flow in the unit cube between two shapes' frames.

A :class:`Deformation` is what the divergence-free method returns besides its
maps (``MatchResult.deformation``): the coefficients of a stationary
divergence-free field in the basis of :mod:`corrlib.deformation.basis`, the
similarity :class:`Frames` placing source and target in the unit cube, and
the RK2 step count per unit time. It evaluates the flow at any time (t in
[0, 1] interpolates, t > 1 extrapolates along the same field) and at any
resolution; :func:`step_interpolator` turns stored RK2 steps into a cheap
``positions(t)`` for scrubbing a sequence.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from corrlib.deformation.basis import DivFreeBasis
from corrlib.deformation.flow import trajectory
from corrlib.errors import InputError


@dataclass(frozen=True)
class Frames:
    """The similarity transforms placing both shapes in the unit cube.

    ``u = scale · (x @ linear.T - centre_x) + 0.5`` for the source,
    ``u = scale · (y - centre_y) + 0.5`` for the target. ``linear`` is the
    source's rotation times its size relative to the target's (a flow that
    preserves volume cannot change the size, so the pre-alignment does).
    """

    linear: np.ndarray  # (3, 3): rotation × the source's scale factor
    scale: float
    centre_x: np.ndarray  # (3,)
    centre_y: np.ndarray  # (3,)

    def source_to_cube(self, points: np.ndarray) -> np.ndarray:
        """(n, 3) float: source points in cube coordinates."""
        return self.scale * (np.asarray(points, dtype=np.float64) @ self.linear.T - self.centre_x) + 0.5

    def target_to_cube(self, points: np.ndarray) -> np.ndarray:
        """(n, 3) float: target points in cube coordinates."""
        return self.scale * (np.asarray(points, dtype=np.float64) - self.centre_y) + 0.5

    def cube_to_target(self, points: np.ndarray) -> np.ndarray:
        """(..., 3) float: cube coordinates back in the target's coordinates."""
        return (np.asarray(points, dtype=np.float64) - 0.5) / self.scale + self.centre_y

    def alignment_undone(self, points: np.ndarray, t: float) -> np.ndarray:
        """(n, 3) float: points in target coordinates moved by the share ``1 − t`` of the pre-alignment's inverse.

        The pre-alignment ``P(x) = s R x − centre_x + centre_y`` (``linear = s R``, a proper rotation times the
        size factor) is undone by a similarity that goes from ``P⁻¹`` at ``t = 0`` to the identity at
        ``t = 1``: about ``centre_y``, the rotation ``Rᵀ`` turned by the angle share ``1 − t`` (the geodesic on
        the rotations), the factor ``s^{-(1 − t)}`` and the remaining shift ``(1 − t) d``, with ``d`` such that
        ``t = 0`` is ``P⁻¹`` exactly. A flow started at the aligned source then starts at the source as given
        and ends where it ends; for ``t ≥ 1`` the points are returned as they are (the extrapolation is the
        flow's, not the alignment's).
        """
        from scipy.spatial.transform import Rotation

        points = np.asarray(points, dtype=np.float64)
        share = 1.0 - min(max(float(t), 0.0), 1.0)
        if share == 0.0:
            return points.copy()
        size = float(np.cbrt(np.linalg.det(self.linear)))
        rotation = self.linear / size
        shift = self.centre_x @ rotation / size - self.centre_y  # P⁻¹(y) = c_y + (y − c_y) R / s + shift
        turn = Rotation.from_rotvec(share * Rotation.from_matrix(rotation.T).as_rotvec()).as_matrix()
        return self.centre_y + size ** -share * (points - self.centre_y) @ turn.T + share * shift

    def as_array(self) -> np.ndarray:
        """(16,) float: linear part (row-major), scale, centre_x, centre_y (how results store it)."""
        return np.concatenate([self.linear.ravel(), [self.scale], self.centre_x, self.centre_y])

    @classmethod
    def from_array(cls, arr) -> "Frames":
        """The inverse of :meth:`as_array`."""
        a = np.asarray(arr, dtype=np.float64).ravel()
        if a.shape != (16,):
            raise InputError(f"a frame record has 16 numbers, got {a.size}")
        if not (np.all(np.isfinite(a)) and a[9] > 0 and np.linalg.det(a[:9].reshape(3, 3)) > 0):
            raise InputError("a frame record needs finite numbers, a positive scale and a linear part that turns "
                             "and scales without a reflection (positive determinant)")
        return cls(a[:9].reshape(3, 3), float(a[9]), a[10:13], a[13:16])


@dataclass(frozen=True)
class StoredSteps:
    """The source vertices at every RK2 step, as computed when the flow was fitted.

    Attributes
    ----------
    times : (s + 1,) float
        Increasing step times from 0.
    positions : (s + 1, n, 3) float
        Source vertices at each time, in target coordinates.
    """

    times: np.ndarray
    positions: np.ndarray


def step_interpolator(times: np.ndarray, steps: np.ndarray):
    """``positions(t)`` from positions at increasing ``times`` (s,) and ``steps`` (s, n, 3).

    Linear in between, exact at the step times, clamped to the stored range.
    """
    def positions(t: float) -> np.ndarray:
        t = float(np.clip(t, times[0], times[-1]))
        i = int(np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2))
        alpha = (t - times[i]) / (times[i + 1] - times[i])
        return ((1.0 - alpha) * steps[i] + alpha * steps[i + 1]).astype(np.float64)

    return positions


class Deformation:
    """The fitted flow, evaluable at any time and resolution.

    Parameters
    ----------
    basis : DivFreeBasis
    coeffs : (K,) float
        Coefficients ``a`` of the field ``v = Σ_k a_k v_k``.
    frames : Frames
    n_steps : int
        T (RK2 steps per unit time).
    source_steps : StoredSteps, optional
        The source vertices along the flow, if they were computed with the fit.
    """

    def __init__(self, basis: DivFreeBasis, coeffs, frames: Frames, n_steps: int,
                 source_steps: StoredSteps | None = None):
        self.basis = basis
        self.coeffs = np.asarray(coeffs, dtype=np.float64)
        self.frames = frames
        self.n_steps = int(n_steps)
        self.source_steps = source_steps

    @classmethod
    def from_arrays(cls, coeffs, frames, n_steps: int, times=None, positions=None) -> "Deformation":
        """Rebuild a deformation from its stored arrays (see ``MatchResult.save``)."""
        coeffs = np.asarray(coeffs, dtype=np.float64).ravel()
        steps = None
        if times is not None and positions is not None:
            steps = StoredSteps(np.asarray(times, dtype=np.float64), np.asarray(positions))
        return cls(DivFreeBasis(coeffs.size), coeffs, Frames.from_array(frames), n_steps, steps)

    def positions(self, points, t: float = 1.0) -> np.ndarray:
        """(n, 3) float: source points (original coordinates) flowed to time ``t``, in target coordinates.

        t = 0 is the source after the pre-alignment (rotated, brought to the
        target's size and placed on it), t = 1 the deformed source, t > 1
        extrapolates. For a sequence that starts at the source as given (the
        alignment undone by the share ``1 − t``), use
        :func:`corrlib.morph.frame_positions`.
        """
        u = self.frames.source_to_cube(points)
        return self.frames.cube_to_target(trajectory(self.basis, u, self.coeffs, t, self.n_steps, keep=False))

    def trajectory(self, points, t_max: float = 1.5) -> StoredSteps:
        """Every RK2 step from 0 to ``t_max`` of ``points`` (n, 3), in target coordinates."""
        u = self.frames.source_to_cube(points)
        steps = trajectory(self.basis, u, self.coeffs, t_max, self.n_steps, keep=True)
        return StoredSteps(np.linspace(0.0, t_max, len(steps)), self.frames.cube_to_target(steps))

    def interpolator(self, points, t_max: float = 1.5):
        """A cheap ``positions(t)`` for scrubbing: the trajectory at every RK2 step, linear in between.

        Exact at the step times; in between it is the piecewise-linear path
        of the integrator (the step size is the flow's own resolution).
        """
        steps = self.trajectory(points, t_max)
        return step_interpolator(steps.times, steps.positions)

    def source_interpolator(self, source_vertices, t_max: float = 1.5):
        """:meth:`interpolator` of the source vertices, reusing the steps stored with the fit if they reach
        ``t_max``."""
        stored = self.source_steps
        if stored is not None and float(stored.times[-1]) >= t_max - 1e-9:
            return step_interpolator(stored.times, stored.positions)
        return self.interpolator(source_vertices, t_max)
