"""Linear assignment (maximisation) backends and slack padding.

* ``"auction"`` (default): Bertsekas' forward auction with ε-scaling,
  compiled with numba (Gauss–Seidel bidding, prices kept across phases).
  The result is within ``n · ε_final`` of the optimum; ``ε_final`` defaults
  to ``1e-9 × (score range) / n``, so the objective matches the exact
  optimum to ~1e-9 of the score range. It releases the GIL (cells can be
  solved in threads) and polls a cancellation flag once per ε phase.
* ``"scipy"``: :func:`scipy.optimize.linear_sum_assignment` (exact, slow on
  smooth kernel scores: ~15 s at n = 3.4k here).

Rectangular problems (``n_rows != n_cols``) are padded with constant dummy
rows or columns, so every element of the smaller side is matched. With a
``slack`` value, every row and column may instead stay unmatched at that
price (thesis Eq. 8.15–8.16): a pair (i, j) is matched only if
``score[i, j] >= slack``. Unmatched elements get -1.

Capacities (``capacity[j]`` rows may share column j) turn the assignment
into a transportation problem with unit supplies; it is solved exactly as
an assignment on copies of the columns (a column with capacity c appears
c times), so every backend and the slack padding apply unchanged.
"""

from __future__ import annotations

import numba
import numpy as np

from corrlib.errors import Cancelled, InputError, ParameterError


@numba.njit(cache=True, nogil=True)
def _auction(benefit, eps_start, eps_final, factor, cancel, prices, row_to_col):
    """Forward auction with ε-scaling on a square benefit matrix (maximisation).

    ``prices`` (n,) is the starting price vector and is updated in place, so a
    sequence of similar problems can be warm-started.
    """
    n = benefit.shape[0]
    col_to_row = np.empty(n, dtype=np.int64)
    eps = max(eps_start, eps_final)
    stack = np.empty(n, dtype=np.int64)
    while True:
        if cancel[0] != 0:
            return False
        row_to_col[:] = -1
        col_to_row[:] = -1
        top = 0
        for i in range(n - 1, -1, -1):
            stack[top] = i
            top += 1
        while top > 0:
            top -= 1
            i = stack[top]
            best = -np.inf
            second = -np.inf
            jbest = 0
            row = benefit[i]
            for j in range(n):
                v = row[j] - prices[j]
                if v > best:
                    second = best
                    best = v
                    jbest = j
                elif v > second:
                    second = v
            if second == -np.inf:  # a 1 x 1 problem
                second = best
            prices[jbest] += best - second + eps
            prev = col_to_row[jbest]
            if prev >= 0:
                row_to_col[prev] = -1
                stack[top] = prev
                top += 1
            col_to_row[jbest] = i
            row_to_col[i] = jbest
        if eps <= eps_final:
            return True
        eps = max(eps / factor, eps_final)


def _pad(score: np.ndarray, slack: float | None) -> np.ndarray:
    n_rows, n_cols = score.shape
    if slack is None:
        if n_rows == n_cols:
            return score
        n = max(n_rows, n_cols)
        fill = score.min() if score.size else 0.0
        out = np.full((n, n), fill, dtype=score.dtype)
        out[:n_rows, :n_cols] = score
        return out
    # rows = real rows + one dummy row per column; cols = real cols + one dummy col per row:
    # a real row left unmatched takes a dummy column at slack/2, a real column a dummy row at slack/2,
    # and each matched pair frees one dummy row and one dummy column that pair up at 0
    n = n_rows + n_cols
    out = np.zeros((n, n), dtype=score.dtype)
    out[:n_rows, :n_cols] = score
    out[:n_rows, n_cols:] = slack / 2.0
    out[n_rows:, :n_cols] = slack / 2.0
    return out


def linear_assignment(score, *, slack: float | None = None, method: str = "auction",
                      eps_final: float | None = None, cancel: np.ndarray | None = None,
                      prices: np.ndarray | None = None, capacity: np.ndarray | None = None) -> np.ndarray:
    """Maximum-score assignment of rows to columns.

    Parameters
    ----------
    score : (n_rows, n_cols) float
        Finite scores (float32 or float64).
    slack : float, optional
        Score of leaving an element unmatched (partial matching).
    method : {"auction", "scipy"}
    eps_final : float, optional
        Final ε of the auction (default ``1e-9 × range / n``).
    cancel : (1,) int8, optional
        Cancellation flag polled by the auction.
    prices : (n,) float, optional
        Warm start of the auction: the column prices of a previous, similar
        problem of the same (padded) size; updated in place. The first ε is
        then 1e-3 of the score range instead of 1/4.
    capacity : (n_cols,) int, optional
        How many rows each column may take (≥ 1; default 1 each).

    Returns
    -------
    (n_rows,) int
        Column of every row, -1 if unmatched.
    """
    s = np.asarray(score)
    if s.ndim != 2 or s.size == 0:
        raise InputError(f"the score must be a non-empty 2-D array, got shape {s.shape}")
    if not np.all(np.isfinite(s)):
        raise InputError("the score contains NaN or infinite values")
    if s.dtype not in (np.float32, np.float64):
        s = s.astype(np.float64)
    copies = None
    if capacity is not None:
        cap = np.asarray(capacity)
        if cap.shape != (s.shape[1],) or not np.issubdtype(cap.dtype, np.integer) or cap.min() < 1:
            raise InputError(f"capacity must hold one integer >= 1 per column ({s.shape[1]}), "
                             f"got {cap.dtype} {cap.shape}")
        if np.any(cap > 1):
            copies = np.repeat(np.arange(s.shape[1]), cap)  # column of every copy
            s = s[:, copies]
    n_rows, n_cols = s.shape
    padded = np.ascontiguousarray(_pad(s, slack))
    if method == "scipy":
        from scipy.optimize import linear_sum_assignment

        rows, cols = linear_sum_assignment(padded, maximize=True)
        row_to_col = np.empty(padded.shape[0], dtype=np.int64)
        row_to_col[rows] = cols
    elif method == "auction":
        n = padded.shape[0]
        span = float(padded.max() - padded.min())
        if eps_final is None:
            eps_final = max(span, 1e-300) * 1e-9 / n
        if eps_final <= 0:
            raise ParameterError(f"eps_final must be positive, got {eps_final}")
        # a bid below the floating-point resolution of the scores does not move a price: two rows would
        # outbid each other forever on tied columns (e.g. equal scores, or the copies of a column)
        eps_final = max(float(eps_final), 16.0 * float(np.spacing(float(np.abs(padded).max()))))
        row_to_col = np.empty(n, dtype=np.int64)
        if span == 0.0:  # all scores equal: every assignment is optimal
            row_to_col[:] = np.arange(n)
        else:
            flag = np.zeros(1, dtype=np.int8) if cancel is None else cancel
            if prices is not None and prices.shape == (n,):
                eps_start = span * 1e-3
            else:
                prices = np.zeros(n)
                eps_start = span / 4.0
            if not _auction(padded, eps_start, eps_final, 5.0, flag, prices, row_to_col):
                raise Cancelled("the computation was cancelled")
    else:
        raise ParameterError(f"unknown assignment method {method!r} (use 'auction' or 'scipy')")
    out = row_to_col[:n_rows].copy()
    out[out >= n_cols] = -1
    if copies is not None:
        out = np.where(out >= 0, copies[np.clip(out, 0, None)], -1)
    return out


def assignment_score(score: np.ndarray, row_to_col: np.ndarray) -> float:
    """Sum of ``score[i, row_to_col[i]]`` over matched rows."""
    rows = np.flatnonzero(row_to_col >= 0)
    return float(np.asarray(score, dtype=np.float64)[rows, row_to_col[rows]].sum())
