"""Linear assignment (maximisation) backends, slack columns and capacities.

* ``"auction"`` (default): Bertsekas' auction with ε-scaling, compiled with
  numba (Gauss–Seidel bidding, prices kept across phases). Rectangular
  problems are solved as asymmetric assignments (Bertsekas & Castañon 1992):
  only the rows of the smaller side bid (forward auction), then unassigned
  columns priced above the cheapest assigned column bid for rows (reverse
  auction) until every unassigned column is at most that cheap, which makes
  the ε-complementary slackness conditions sufficient for optimality without
  dummy rows. Every row keeps a list of its :data:`N_CANDIDATES` best columns
  and a bound on the value of all others (prices only rise during bidding, and
  a reverse step's price drop is added to the bounds), so most bids cost
  O(N_CANDIDATES) instead of a scan of the row. The result is within
  ``m · ε_final`` of the optimum (``m`` bidding rows); ``ε_final`` defaults to
  ``1e-9 × (score range) / max(n_rows, n_cols)``, so the objective matches
  the exact optimum to ~1e-9 of the score range — but never below the
  precision of the scores themselves (``finfo(dtype).eps × max |score|``):
  a float32 score is only known to that, and finer bids would only reorder
  its rounding (the objective's own rounding error over ``m`` rows is of the
  same order as the bound ``m · ε``). It releases the GIL (cells
  can be solved in threads) and polls a cancellation flag once per ε phase.
* ``"scipy"``: :func:`scipy.optimize.linear_sum_assignment` (exact; the
  Jonker–Volgenant algorithm is slow on the smooth, near-tied scores of
  heat kernels).

Rectangular problems (``n_rows != n_cols``): every element of the smaller
side is matched. With a ``slack`` value, every row and column may instead
stay unmatched at that price (thesis Eq. 8.15–8.16; the rows of the smaller
side get one slack column each): a pair (i, j) is matched only if
``score[i, j] >= slack``. Unmatched elements get -1.

Capacities (``capacity[j]`` rows may share column j) turn the assignment
into a transportation problem with unit supplies; it is solved exactly as
an assignment on copies of the columns (a column with capacity c appears
c times), so every backend and the slack columns apply unchanged.
"""

from __future__ import annotations

import numba
import numpy as np

from corrlib.errors import Cancelled, InputError, ParameterError

#: length of every row's list of best columns in the auction
N_CANDIDATES = 8
#: bids the auction may spend, per row and per √(columns), before the exact Jonker–Volgenant solver takes
#: over. The auction is pseudo-polynomial: on near-tied columns (e.g. the copies of a column with a
#: capacity, on an exactly symmetric shape) rows outbid each other by ε for a very long time.
BID_BUDGET = 20


@numba.njit(cache=True, nogil=True)
def _best_of_row(row, prices, n_keep, best_v, best_j):
    """The ``n_keep`` largest values ``row[j] - prices[j]``, descending, into ``best_v``/``best_j`` (n_keep,)."""
    count = 0
    last = n_keep - 1
    for j in range(row.shape[0]):
        v = row[j] - prices[j]
        if count < n_keep:
            p = count
            count += 1
        elif v > best_v[last]:
            p = last
        else:
            continue
        while p > 0 and best_v[p - 1] < v:  # insertion into the sorted buffer
            best_v[p] = best_v[p - 1]
            best_j[p] = best_j[p - 1]
            p -= 1
        best_v[p] = v
        best_j[p] = j


@numba.njit(cache=True, nogil=True)
def _auction(benefit, benefit_t, eps_start, eps_final, factor, cancel, prices, row_to_col, n_cand, max_bids):
    """Forward–reverse auction with ε-scaling (maximisation), ``m <= n``.

    Parameters
    ----------
    benefit : (m, n) float
    benefit_t : (n, m) float
        The transposed benefit (C order), read by the reverse steps; any array if ``m == n``.
    prices : (n,) float
        Starting prices, updated in place (warm start of a similar problem).
    row_to_col : (m,) int
        Output: the column of every row.
    n_cand : int
        Candidate list length (< 2: plain scans).
    max_bids : int
        Budget of bids (forward and reverse) over all ε phases.

    Returns
    -------
    int
        1: solved; 0: cancelled; -1: the bid budget ran out (a price war, see :data:`BID_BUDGET`).
    """
    m, n = benefit.shape
    col_to_row = np.empty(n, dtype=np.int64)
    profit = np.zeros(m)  # π_i = value of row i's column at the current prices, within ε of its best
    eps = max(eps_start, eps_final)
    stack = np.empty(max(m, n), dtype=np.int64)
    n_list = min(n_cand, n - 1)
    use_lists = n_list >= 2
    cand = np.empty((m, max(n_list, 1)), dtype=np.int64)
    # bound[i]: largest value of a column outside row i's list when it was built (inf: no list yet);
    # values outside the list can only have risen by the reverse steps' price drops since then
    bound = np.full(m, np.inf)
    drop_at = np.zeros(m)
    drop = 0.0
    n_keep = min(max(n_list + 1, 2), n)  # values kept by a full scan: the list, its bound, at least the top two
    best_v = np.empty(max(n_keep, 2))
    best_j = np.empty(max(n_keep, 2), dtype=np.int64)
    bids = 0
    while True:
        if cancel[0] != 0:
            return 0
        row_to_col[:] = -1
        col_to_row[:] = -1
        stack[:m] = np.arange(m - 1, -1, -1)  # row 0 bids first
        top = m
        # forward auction: unassigned rows bid until every row holds a column
        while top > 0:
            bids += 1
            if bids > max_bids:
                return -1
            top -= 1
            i = stack[top]
            row = benefit[i]
            listed = False
            best = -np.inf
            second = -np.inf
            jbest = 0
            if use_lists and bound[i] < np.inf:
                for q in range(n_list):
                    j = cand[i, q]
                    v = row[j] - prices[j]
                    if v > best:
                        second = best
                        best = v
                        jbest = j
                    elif v > second:
                        second = v
                listed = second >= bound[i] + (drop - drop_at[i])
            if not listed:
                _best_of_row(row, prices, n_keep, best_v, best_j)
                if use_lists:
                    cand[i, :] = best_j[:n_list]
                    bound[i] = best_v[n_list]
                    drop_at[i] = drop
                best, jbest = best_v[0], best_j[0]
                second = best_v[1] if n_keep >= 2 else best  # a single column: the bid is ε
            prices[jbest] += best - second + eps
            profit[i] = second - eps
            prev = col_to_row[jbest]
            if prev >= 0:
                row_to_col[prev] = -1
                stack[top] = prev
                top += 1
            col_to_row[jbest] = i
            row_to_col[i] = jbest
        if n > m:
            # reverse auction: unassigned columns priced above λ (the cheapest assigned column) bid for rows,
            # until no unassigned column is dearer than an assigned one
            lam = np.inf
            for j in range(n):
                if col_to_row[j] >= 0 and prices[j] < lam:
                    lam = prices[j]
            top = 0
            for j in range(n):
                if col_to_row[j] < 0 and prices[j] > lam:
                    stack[top] = j
                    top += 1
            while top > 0:
                bids += 1
                if bids > max_bids:
                    return -1
                top -= 1
                j = stack[top]
                col = benefit_t[j]
                _best_of_row(col, profit, min(2, m), best_v, best_j)
                beta, ibest = best_v[0], best_j[0]
                omega = best_v[1] if m >= 2 else -np.inf
                old = prices[j]
                if lam >= beta - eps:
                    prices[j] = lam
                else:
                    prices[j] = max(lam, omega - eps)
                    profit[ibest] = col[ibest] - prices[j]
                    k = row_to_col[ibest]
                    col_to_row[k] = -1
                    row_to_col[ibest] = j
                    col_to_row[j] = ibest
                    if prices[k] > lam:
                        stack[top] = k
                        top += 1
                drop += old - prices[j]
        if eps <= eps_final:
            return 1
        eps = max(eps / factor, eps_final)


def _with_slack_columns(base: np.ndarray, slack: float) -> np.ndarray:
    """(r, c + r): the score with one slack column per bidding row (thesis Eq. 8.15–8.16).

    Leaving row i and column j unmatched scores ``slack / 2`` each, so a matched pair gains
    ``score[i, j] - slack`` over leaving both unmatched: up to a constant, the partial matching is the
    assignment of every row to a real column at ``score[i, j]`` or to its own slack column at ``slack``.
    The other rows' slack columns score far below every alternative (they are never taken).
    """
    r, c = base.shape
    lo, hi = min(float(base.min()), slack), max(float(base.max()), slack)
    gap = hi - lo if hi > lo else max(abs(lo), 1.0)
    out = np.empty((r, c + r), dtype=np.result_type(base.dtype, np.float32))
    out[:, :c] = base
    out[:, c:] = lo - gap
    out[np.arange(r), c + np.arange(r)] = slack
    return out


def _effective_slack(base: np.ndarray, slack: float) -> float:
    """The slack clipped to the range where its value still matters; the optimal assignment is unchanged.

    With ``r`` bidding rows and score span ``d``, a slack below ``min − r d`` already makes every
    maximum-cardinality matching beat every smaller one, and a slack above ``max`` leaves everything
    unmatched; values beyond ``min − (r + 1) d`` and ``max + d`` give the same optimum, while keeping the
    auction's ε (relative to the score range) and its floating-point resolution meaningful.
    """
    lo, hi = float(base.min()), float(base.max())
    span = max(hi - lo, abs(hi), 1e-300)
    return float(np.clip(slack, lo - (base.shape[0] + 1) * span, hi + span))


@numba.njit(cache=True, nogil=True)
def _duality_gap(s: np.ndarray, prices: np.ndarray, row_to_col: np.ndarray) -> float:
    """``Σ_i max_j (s_ij − p_j) + Σ_j p_j − Σ_i s_{i,σ(i)}`` (≥ 0) for a permutation ``σ`` of the columns of a
    square ``s``: how far prices ``p`` and ``σ`` are from being optimal together (zero exactly when both are,
    by LP duality)."""
    m, n = s.shape
    gap = 0.0
    for j in range(n):
        gap += prices[j]
    for i in range(m):
        best = -np.inf
        for j in range(n):
            v = s[i, j] - prices[j]
            if v > best:
                best = v
        gap += best - s[i, row_to_col[i]]
    return max(gap, 0.0)


def _auction_solve(s: np.ndarray, eps_final: float | None, eps_start: float | None, cancel, prices,
                   warm_map=None) -> np.ndarray:
    """(m,) int: column of every row of ``s`` (m, n), m <= n, by the forward–reverse auction (``warm_map``: see
    :func:`linear_assignment`)."""
    m, n = s.shape
    span = float(s.max() - s.min())
    if eps_final is None:
        # 1e-9 of the range per row, but no finer than the scores' own precision: a float32 score is known
        # to about eps32 * |s|, so bids below that only reorder ties of the rounding
        eps_final = max(max(span, 1e-300) * 1e-9 / n, float(np.finfo(s.dtype).eps) * float(np.abs(s).max()))
    if not (np.isfinite(eps_final) and eps_final > 0):  # NaN would never stop the ε-scaling
        raise ParameterError(f"eps_final must be positive and finite, got {eps_final}")
    # a bid below the floating-point resolution of the scores does not move a price: two rows would
    # outbid each other forever on tied columns (e.g. equal scores, or the copies of a column)
    eps_final = max(float(eps_final), 16.0 * float(np.spacing(float(np.abs(s).max()))))
    row_to_col = np.empty(m, dtype=np.int64)
    if span == 0.0:  # all scores equal: every assignment is optimal
        row_to_col[:] = np.arange(m)
        return row_to_col
    flag = np.zeros(1, dtype=np.int8) if cancel is None else cancel
    warm = prices is not None and prices.shape == (n,) and bool(np.any(prices != prices[0]))
    if prices is None or prices.shape != (n,):
        prices = np.zeros(n)
    if eps_start is None:
        if warm and warm_map is not None and m == n:
            # the ε at which the warm state's own suboptimality is what ε-complementary slackness allows (m ε):
            # smaller, and the rows outbid each other in tiny steps all the way from another problem's prices;
            # larger, and prices that are nearly right are undone
            eps_start = min(max(_duality_gap(s, prices, warm_map) / (m * span), 1e-12), 0.25)
        else:
            eps_start = 1e-3 if warm else 0.25
    if not 0 < eps_start <= 1:
        raise ParameterError(f"eps_start must lie in (0, 1] (a fraction of the score range), got {eps_start}")
    eps_start *= span
    s_t = np.ascontiguousarray(s.T) if n > m else s
    status = _auction(s, s_t, eps_start, eps_final, 5.0, flag, prices, row_to_col, N_CANDIDATES,
                      int(BID_BUDGET * m * max(m, n) ** 0.5))
    if status == 0:
        raise Cancelled("the computation was cancelled")
    if status < 0:  # a price war on near-tied columns: the strongly polynomial exact solver instead
        from scipy.optimize import linear_sum_assignment

        rows, cols = linear_sum_assignment(s, maximize=True)
        row_to_col[rows] = cols
    return row_to_col


def linear_assignment(score, *, slack: float | None = None, method: str = "auction",
                      eps_final: float | None = None, eps_start: float | None = None,
                      cancel: np.ndarray | None = None, prices: np.ndarray | None = None,
                      capacity: np.ndarray | None = None, warm_map: np.ndarray | None = None) -> np.ndarray:
    """Maximum-score assignment of rows to columns.

    Parameters
    ----------
    score : (n_rows, n_cols) float
        Finite scores (float32 or float64).
    slack : float, optional
        Score of leaving an element unmatched (partial matching).
    method : {"auction", "scipy"}
    eps_final : float, optional
        Final ε of the auction (default ``1e-9 × range / max(n_rows, n_cols)``, at least the scores'
        precision ``finfo(dtype).eps × max |score|``).
    eps_start : float, optional
        First ε of the auction as a fraction of the score range. Default: 1/4 from cold prices; from warm
        prices with a ``warm_map``, their duality gap per row (``(Σ_i max_j (s_ij − p_j) + Σ_j p_j −
        Σ_i s_{i,σ(i)}) / m`` over the score range, at most 1/4): prices from a nearly equal problem are only
        refined, prices from a less similar one are first moved in large steps; from warm prices alone, 1e-3.
    cancel : (1,) int8, optional
        Cancellation flag polled by the auction.
    prices : (n,) float, optional
        Warm start of the auction: the column prices of a previous, similar
        problem of the same size (``n``: the columns of the problem the
        auction solves — the larger side, plus the smaller one with slack);
        updated in place. Prices that are all equal (e.g. the zeros of a
        first call) count as a cold start.
    capacity : (n_cols,) int, optional
        How many rows each column may take (≥ 1; default 1 each).
    warm_map : (n_rows,) int, optional
        The permutation the warm ``prices`` came with (the previous problem's solution), for the first ε;
        read for square problems without slack or capacities only.

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
    if slack is not None and not np.isfinite(slack):
        raise InputError(f"the slack must be a finite number, got {slack}")
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
    # the auction's bidders are the rows of the smaller side
    transposed = n_rows > n_cols
    base = np.ascontiguousarray(s.T if transposed else s)
    problem = base if slack is None else _with_slack_columns(base, _effective_slack(base, float(slack)))
    if method == "scipy":
        from scipy.optimize import linear_sum_assignment

        rows, cols = linear_sum_assignment(problem, maximize=True)
        small_to_large = np.empty(problem.shape[0], dtype=np.int64)
        small_to_large[rows] = cols
    elif method == "auction":
        warm = None
        if warm_map is not None and slack is None and copies is None and n_rows == n_cols:
            warm = np.asarray(warm_map)
            if warm.shape != (n_rows,) or not np.issubdtype(warm.dtype, np.integer) or \
                    not np.array_equal(np.sort(warm), np.arange(n_rows)):
                raise InputError(f"warm_map must be a permutation of the {n_cols} columns, got {warm.dtype} "
                                 f"{warm.shape}")
            warm = warm.astype(np.int64)
        small_to_large = _auction_solve(problem, eps_final, eps_start, cancel, prices, warm)
    else:
        raise ParameterError(f"unknown assignment method {method!r} (use 'auction' or 'scipy')")
    small_to_large[small_to_large >= base.shape[1]] = -1  # slack columns: unmatched
    if transposed:
        row_to_col = -np.ones(n_rows, dtype=np.int64)
        matched = np.flatnonzero(small_to_large >= 0)
        row_to_col[small_to_large[matched]] = matched
    else:
        row_to_col = small_to_large
    if copies is not None:
        row_to_col = np.where(row_to_col >= 0, copies[np.clip(row_to_col, 0, None)], -1)
    return row_to_col


def area_capacities(n_rows: int, masses: np.ndarray) -> np.ndarray:
    """(n_cols,) int ≥ 1: rows a column of mass ``m_j`` may take, ``ceil(n_rows · m_j / Σ m)``.

    The columns' share of the rows follows their share of the measure, so an
    assignment with these capacities couples two differently sampled shapes
    by area instead of by sample count (a bijection between independently
    remeshed surfaces has to slide samples to absorb the density difference).
    """
    m = np.asarray(masses, dtype=np.float64)
    if m.ndim != 1 or m.size == 0 or not np.all(np.isfinite(m)) or m.min() < 0 or m.sum() <= 0:
        raise InputError(f"masses must be a non-empty 1-D array of finite non-negative values with a "
                         f"positive sum, got shape {m.shape}")
    share = int(n_rows) * m / m.sum()
    return np.maximum(1, np.ceil(share - 1e-9)).astype(np.int64)


def assignment_score(score: np.ndarray, row_to_col: np.ndarray) -> float:
    """Sum of ``score[i, row_to_col[i]]`` over matched rows."""
    rows = np.flatnonzero(row_to_col >= 0)
    return float(np.asarray(score, dtype=np.float64)[rows, row_to_col[rows]].sum())
