"""Flowing points along a divergence-free velocity field (thesis Eq. 10.13 and C.15).

The deformation is the time-1 flow of the stationary field
``v(x) = Σ_k a_k v_k(x)`` (:mod:`.basis`), integrated by T explicit midpoint
(RK2) steps of size h = 1/T (Eq. 10.13)::

    m_t     = x_t + (h/2) v(x_t)
    x_{t+1} = x_t + h v(m_t)

Evaluating the flow at time t runs ``ceil(t T)`` steps of size ``t / ceil(t T)``
(t > 1 extrapolates along the same field; t < 0 runs it backwards).

The derivative of the end points with respect to the coefficients follows
the recursion of Eq. C.15, with ``V(x)`` the (3, K) matrix of basis values
and ``J(x) = Σ_k a_k ∂v_k/∂x`` the (3, 3) Jacobian of the velocity::

    ∂m_t/∂a     = ∂x_t/∂a + (h/2) [V(x_t) + J(x_t) ∂x_t/∂a]
    ∂x_{t+1}/∂a = ∂x_t/∂a + h     [V(m_t) + J(m_t) ∂m_t/∂a]

Two implementations: :func:`flow_with_jacobian` (compiled, one point per
task, the (3, K) derivative in cache) for the fitting, and :func:`flow`
(velocity only, separable sums vectorised over blocks of points) for flowing
full-resolution meshes and animation frames.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from corrlib.deformation.basis import DivFreeBasis
from corrlib.errors import InputError, ParameterError



def check_points(points, name: str = "points", min_count: int = 0) -> np.ndarray:
    """(n, 3) float64 points, or :class:`InputError` naming the problem (shape, count, NaN/inf)."""
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise InputError(f"{name} must have shape (n, 3), got {p.shape}")
    if len(p) < min_count:
        raise InputError(f"{name}: {len(p)} points; at least {min_count} are needed")
    if not np.all(np.isfinite(p)):
        raise InputError(f"{name} contain NaN or inf")
    return p


def step_count(t: float, n_steps: int) -> tuple[int, float]:
    """Steps and step size for time ``t`` at the resolution of ``n_steps`` steps per unit time."""
    if int(n_steps) != n_steps or n_steps < 1:
        raise ParameterError(f"the number of flow steps T must be a positive integer, got {n_steps!r}")
    if not math.isfinite(t):
        raise ParameterError(f"the flow time must be finite, got {t!r}")
    steps = max(1, math.ceil(abs(t) * n_steps - 1e-9))
    return steps, t / steps


# ----------------------------------------------------------------------------- velocity only

_BLOCK = 128  # points per SIMD block of the velocity kernel


def _coefficient_tensor(basis: DivFreeBasis, coeffs) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients as a dense (3, M, M, M) tensor ``A[d, j1-1, j2-1, j3-1]`` and the (M, M) count of j3 used."""
    a = basis.padded(coeffs).reshape(-1, 3)
    m = basis.max_freq
    j = basis.freqs - 1
    tens = np.zeros((3, m, m, m))
    for d in range(3):
        tens[d, j[:, 0], j[:, 1], j[:, 2]] = a[:, d]
    top = np.zeros((m, m), dtype=np.int64)
    np.maximum.at(top, (j[:, 0], j[:, 1]), j[:, 2] + 1)
    return tens, top


@numba.njit(cache=True, parallel=True, fastmath=True, nogil=True)
def _velocity_kernel(x, tens, top, out):
    """Separable evaluation of Eq. 10.11 summed with the coefficients, vectorised over blocks of points.

    v₁ = Σ_{j1,j2} [s₁c₂ Σ_{j3} a₃ s₃ − s₁s₂ Σ_{j3} a₂ c₃], and cyclically (a_d: coefficient of curl(φ e_d)).
    """
    n = x.shape[0]
    m = tens.shape[1]
    n_blocks = (n + _BLOCK - 1) // _BLOCK
    for b in numba.prange(n_blocks):
        lo = b * _BLOCK
        size = min(n, lo + _BLOCK) - lo
        s = np.empty((3, m, _BLOCK))
        c = np.empty((3, m, _BLOCK))
        for d in range(3):
            for f in range(m):
                w = math.pi * (f + 1)
                for i in range(size):
                    s[d, f, i] = math.sin(w * x[lo + i, d])
                    c[d, f, i] = w * math.cos(w * x[lo + i, d])
        v1 = np.zeros(_BLOCK)
        v2 = np.zeros(_BLOCK)
        v3 = np.zeros(_BLOCK)
        a2s3 = np.empty(_BLOCK)
        a1c3 = np.empty(_BLOCK)
        a0c3 = np.empty(_BLOCK)
        a1s3 = np.empty(_BLOCK)
        a0s3 = np.empty(_BLOCK)
        for j1 in range(m):
            for j2 in range(m):
                count = top[j1, j2]
                if count == 0:
                    continue
                a2s3[:] = 0.0
                a1c3[:] = 0.0
                a0c3[:] = 0.0
                a1s3[:] = 0.0
                a0s3[:] = 0.0
                for j3 in range(count):
                    e0 = tens[0, j1, j2, j3]
                    e1 = tens[1, j1, j2, j3]
                    e2 = tens[2, j1, j2, j3]
                    for i in range(size):
                        s3 = s[2, j3, i]
                        c3 = c[2, j3, i]
                        a2s3[i] += e2 * s3
                        a1c3[i] += e1 * c3
                        a0c3[i] += e0 * c3
                        a1s3[i] += e1 * s3
                        a0s3[i] += e0 * s3
                for i in range(size):
                    s1c2 = s[0, j1, i] * c[1, j2, i]
                    s1s2 = s[0, j1, i] * s[1, j2, i]
                    c1s2 = c[0, j1, i] * s[1, j2, i]
                    v1[i] += s1c2 * a2s3[i] - s1s2 * a1c3[i]
                    v2[i] += s1s2 * a0c3[i] - c1s2 * a2s3[i]
                    v3[i] += c1s2 * a1s3[i] - s1c2 * a0s3[i]
        for i in range(size):
            out[lo + i, 0] = v1[i]
            out[lo + i, 1] = v2[i]
            out[lo + i, 2] = v3[i]


class _VelocityTensors:
    """The velocity field of fixed coefficients, callable on (n, 3) points."""

    def __init__(self, basis: DivFreeBasis, coeffs):
        self.tens, self.top = _coefficient_tensor(basis, coeffs)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        out = np.empty_like(x)
        _velocity_kernel(np.ascontiguousarray(x), self.tens, self.top, out)
        return out


def velocity(basis: DivFreeBasis, points, coeffs) -> np.ndarray:
    """(n, 3) float: the velocity ``Σ_k a_k v_k`` at ``points`` (fast separable evaluation)."""
    p = check_points(points)
    return _VelocityTensors(basis, coeffs)(p)


def trajectory(basis: DivFreeBasis, points, coeffs, t: float = 1.0, n_steps: int = 20,
               keep: bool = True) -> np.ndarray:
    """Flow ``points`` to time ``t`` by RK2 (Eq. 10.13).

    Parameters
    ----------
    basis : DivFreeBasis
    points : (n, 3) float
        Start positions (in the unit-cube frame).
    coeffs : (K,) float
    t : float
        End time (t > 1 extrapolates, t < 0 runs backwards).
    n_steps : int
        T, steps per unit time.
    keep : bool
        Return every step (``(s + 1, n, 3)``) instead of the end points only.

    Returns
    -------
    (n, 3) or (s + 1, n, 3) float
        With ``s = ceil(|t| T)`` steps.
    """
    p = check_points(points)
    steps, h = step_count(t, n_steps)
    vel = _VelocityTensors(basis, coeffs)
    out = np.empty((steps + 1,) + p.shape) if keep else None
    x = p.copy()
    if keep:
        out[0] = x
    for step in range(steps):
        mid = x + 0.5 * h * vel(x)
        x = x + h * vel(mid)
        if keep:
            out[step + 1] = x
    return out if keep else x


def flow(basis: DivFreeBasis, points, coeffs, t: float = 1.0, n_steps: int = 20) -> np.ndarray:
    """(n, 3) float: ``points`` flowed to time ``t`` (see :func:`trajectory`)."""
    return trajectory(basis, points, coeffs, t, n_steps, keep=False)


# ----------------------------------------------------------------------------- with derivatives (numba)


@numba.njit(cache=True, fastmath=True, nogil=True)
def _eval_gradients(x, a, freqs, s, c, ss, pairs, grad, vel, jac):
    """Velocity (3,), its Jacobian (3, 3) and every potential's gradient ``∇φ_q`` (3, Q) at ``x``.

    The fields of potential ``q`` are ``∇φ_q × e_d`` up to sign (module docstring), so the gradients are all
    the field values carry. ``pairs`` (6, M, M) is scratch for the products of the first two axes' tables.
    """
    n_freq = s.shape[1]
    for d in range(3):
        for m in range(n_freq):
            w = math.pi * (m + 1)
            arg = w * x[d]
            s[d, m] = math.sin(arg)
            c[d, m] = w * math.cos(arg)
            ss[d, m] = -w * w * s[d, m]
    for i1 in range(n_freq):
        for i2 in range(n_freq):
            pairs[0, i1, i2] = s[0, i1] * s[1, i2]
            pairs[1, i1, i2] = s[0, i1] * c[1, i2]
            pairs[2, i1, i2] = c[0, i1] * s[1, i2]
            pairs[3, i1, i2] = ss[0, i1] * s[1, i2]
            pairs[4, i1, i2] = s[0, i1] * ss[1, i2]
            pairs[5, i1, i2] = c[0, i1] * c[1, i2]
    v0 = 0.0
    v1 = 0.0
    v2 = 0.0
    j00 = 0.0
    j01 = 0.0
    j02 = 0.0
    j10 = 0.0
    j11 = 0.0
    j12 = 0.0
    j20 = 0.0
    j21 = 0.0
    j22 = 0.0
    for q in range(freqs.shape[0]):
        i1 = freqs[q, 0] - 1
        i2 = freqs[q, 1] - 1
        i3 = freqs[q, 2] - 1
        p_ss = pairs[0, i1, i2]
        p_sc = pairs[1, i1, i2]
        p_cs = pairs[2, i1, i2]
        s3 = s[2, i3]
        c3 = c[2, i3]
        g1 = p_cs * s3
        g2 = p_sc * s3
        g3 = p_ss * c3
        h11 = pairs[3, i1, i2] * s3
        h22 = pairs[4, i1, i2] * s3
        h33 = p_ss * ss[2, i3]
        h12 = pairs[5, i1, i2] * s3
        h13 = p_cs * c3
        h23 = p_sc * c3
        a0 = a[3 * q]
        a1 = a[3 * q + 1]
        a2 = a[3 * q + 2]
        v0 += a2 * g2 - a1 * g3
        v1 += a0 * g3 - a2 * g1
        v2 += a1 * g1 - a0 * g2
        j00 += a2 * h12 - a1 * h13
        j01 += a2 * h22 - a1 * h23
        j02 += a2 * h23 - a1 * h33
        j10 += a0 * h13 - a2 * h11
        j11 += a0 * h23 - a2 * h12
        j12 += a0 * h33 - a2 * h13
        j20 += a1 * h11 - a0 * h12
        j21 += a1 * h12 - a0 * h22
        j22 += a1 * h13 - a0 * h23
        grad[0, q] = g1
        grad[1, q] = g2
        grad[2, q] = g3
    vel[0] = v0
    vel[1] = v1
    vel[2] = v2
    jac[0, 0] = j00
    jac[0, 1] = j01
    jac[0, 2] = j02
    jac[1, 0] = j10
    jac[1, 1] = j11
    jac[1, 2] = j12
    jac[2, 0] = j20
    jac[2, 1] = j21
    jac[2, 2] = j22


#: the fields ``3q + d`` as ``curl(φ_q e_d)_i = sign · ∂_j φ_q``: (j, sign) for every (d, i)
_CURL_TERMS = np.array([[[0, 0], [2, 1], [1, -1]],
                        [[2, -1], [0, 0], [0, 1]],
                        [[1, 1], [0, -1], [0, 0]]], dtype=np.int64)


@numba.njit(cache=True, fastmath=True, nogil=True)
def _sensitivity_rk2(dx, d, grad_x, grad_m, jac_x, jac_m, h, coef):
    """One RK2 step of Eq. C.15 for the fields ``3q + d`` of every potential, in place.

    ``dx`` (3, Q): ``∂x/∂a_{3q+d}``; ``grad_x``, ``grad_m`` (3, Q): the potentials' gradients at the step's
    start and midpoint, whose entries make the fields' values (:data:`_CURL_TERMS`). ``m = dx + h/2 (v(x) +
    J(x) dx)``, then ``dx ← dx + h (v(mid) + J(mid) m)``: both stages per column in registers, one pass over
    ``dx``. ``coef`` (24,) is scratch of ``dx``'s dtype, so that with float32 sensitivities the loop runs in
    float32 lanes.
    """
    half = 0.5 * h
    for i in range(3):
        for j in range(3):
            coef[3 * i + j] = jac_x[i, j] * half
            coef[9 + 3 * i + j] = jac_m[i, j] * h
        coef[18 + i] = _CURL_TERMS[d, i, 1] * half
        coef[21 + i] = _CURL_TERMS[d, i, 1] * h
    x00, x01, x02, x10, x11, x12, x20, x21, x22 = (coef[0], coef[1], coef[2], coef[3], coef[4], coef[5],
                                                   coef[6], coef[7], coef[8])
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = (coef[9], coef[10], coef[11], coef[12], coef[13], coef[14],
                                                   coef[15], coef[16], coef[17])
    sx0, sx1, sx2, sm0, sm1, sm2 = coef[18], coef[19], coef[20], coef[21], coef[22], coef[23]
    gx0, gx1, gx2 = grad_x[_CURL_TERMS[d, 0, 0]], grad_x[_CURL_TERMS[d, 1, 0]], grad_x[_CURL_TERMS[d, 2, 0]]
    gm0, gm1, gm2 = grad_m[_CURL_TERMS[d, 0, 0]], grad_m[_CURL_TERMS[d, 1, 0]], grad_m[_CURL_TERMS[d, 2, 0]]
    for q in range(dx.shape[1]):
        d0 = dx[0, q]
        d1 = dx[1, q]
        d2 = dx[2, q]
        e0 = d0 + sx0 * gx0[q] + x00 * d0 + x01 * d1 + x02 * d2
        e1 = d1 + sx1 * gx1[q] + x10 * d0 + x11 * d1 + x12 * d2
        e2 = d2 + sx2 * gx2[q] + x20 * d0 + x21 * d1 + x22 * d2
        dx[0, q] = d0 + sm0 * gm0[q] + m00 * e0 + m01 * e1 + m02 * e2
        dx[1, q] = d1 + sm1 * gm1[q] + m10 * e0 + m11 * e1 + m12 * e2
        dx[2, q] = d2 + sm2 * gm2[q] + m20 * e0 + m21 * e1 + m22 * e2


@numba.njit(cache=True, parallel=True, fastmath=True, nogil=True)
def _flow_jacobian_kernel(points, a, freqs, n_freq, steps, h, out_x, out_dx):
    n_pot = freqs.shape[0]
    n_out = out_dx.shape[2]
    for n in numba.prange(points.shape[0]):
        s = np.empty((3, n_freq))
        c = np.empty((3, n_freq))
        ss = np.empty((3, n_freq))
        pairs = np.empty((6, n_freq, n_freq))
        grad_x = np.empty((3, n_pot), out_dx.dtype)
        grad_m = np.empty((3, n_pot), out_dx.dtype)
        dx = np.zeros((3, 3, n_pot), out_dx.dtype)  # [d]: the fields 3q + d
        vel = np.empty(3)
        jac_x = np.empty((3, 3))
        jac_m = np.empty((3, 3))
        coef = np.empty(24, out_dx.dtype)
        x = points[n].copy()
        mid = np.empty(3)
        for _ in range(steps):
            _eval_gradients(x, a, freqs, s, c, ss, pairs, grad_x, vel, jac_x)
            for i in range(3):
                mid[i] = x[i] + 0.5 * h * vel[i]
            _eval_gradients(mid, a, freqs, s, c, ss, pairs, grad_m, vel, jac_m)
            for i in range(3):
                x[i] += h * vel[i]
            for d in range(3):
                _sensitivity_rk2(dx[d], d, grad_x, grad_m, jac_x, jac_m, h, coef)
        out_x[n] = x
        for i in range(3):
            for q in range(n_pot):
                for d in range(3):
                    k = 3 * q + d
                    if k < n_out:
                        out_dx[n, i, k] = dx[d, i, q]


def flow_with_jacobian(basis: DivFreeBasis, points, coeffs, n_steps: int = 20,
                       dtype=np.float64) -> tuple[np.ndarray, np.ndarray]:
    """Flow ``points`` to t = 1 and differentiate the end points (Eq. C.15).

    Parameters
    ----------
    basis : DivFreeBasis
    points : (n, 3) float
    coeffs : (K,) float
    n_steps : int
        T.
    dtype : numpy dtype
        Of the returned derivative (float32 halves the memory of the Gauss–Newton system).

    Returns
    -------
    x : (n, 3) float64
        End points.
    dx_da : (n, 3, K)
        ``∂x_n / ∂a_k``.
    """
    p = check_points(points)
    steps, h = step_count(1.0, n_steps)
    a = basis.padded(coeffs)
    out_x = np.empty_like(p)
    out_dx = np.empty((len(p), 3, basis.n_fields), dtype=dtype)
    _flow_jacobian_kernel(p, a, basis.freqs, basis.max_freq, steps, h, out_x, out_dx)
    return out_x, out_dx
