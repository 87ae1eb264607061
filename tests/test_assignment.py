"""Linear assignment: the auction equals the exact optimum; slack and rectangular problems."""

import itertools

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from corrlib.assignment import assignment_score, linear_assignment
from corrlib.errors import Cancelled, InputError, ParameterError


def exact_value(score):
    r, c = linear_sum_assignment(score, maximize=True)
    return float(score[r, c].sum())


@pytest.mark.slow
def test_auction_matches_exact_optimum_on_random_instances():
    rng = np.random.default_rng(0)
    for trial in range(200):
        n = int(rng.integers(1, 301))
        m = n if trial % 4 else int(rng.integers(1, 301))
        score = rng.normal(size=(n, m)) * 10 ** rng.uniform(-3, 3)
        if trial % 5 == 0:
            score = np.round(score)  # many ties
        sol = linear_assignment(score)
        matched = sol[sol >= 0]
        assert matched.size == min(n, m) and np.unique(matched).size == matched.size
        span = score.max() - score.min() + 1e-300
        assert abs(assignment_score(score, sol) - exact_value(score)) <= 1e-8 * span


@pytest.mark.slow
def test_auction_on_kernel_structured_scores(wolf_pair):
    from corrlib.geometry.sampling import farthest_point_sampling
    from corrlib.geometry.spectrum import mesh_spectrum

    w0, w1 = wolf_pair
    s0, s1 = mesh_spectrum(w0, 100), mesh_spectrum(w1, 100)
    idx = farthest_point_sampling(w0.vertices, 400)
    rng = np.random.default_rng(1)
    for t in (5.0, 50.0, 500.0):  # smooth kernels are the hard case for assignment solvers
        noisy = idx[rng.permutation(idx.size)]
        c = s1.evecs[noisy].T @ s0.evecs[idx]
        d0, d1 = np.exp(-t * s0.evals), np.exp(-t * s1.evals)
        score = (s1.evecs[idx] * d1) @ c @ (s0.evecs[idx] * d0).T
        for dtype in (np.float64, np.float32):
            s = score.astype(dtype)
            sol = linear_assignment(s)
            assert abs(assignment_score(s, sol) - exact_value(s.astype(np.float64))) <= 1e-6 * np.ptp(score)


def brute_force_partial(score, slack):
    """Best partial matching: matched scores plus slack/2 per unmatched row and column."""
    n, m = score.shape
    best = -np.inf
    for k in range(min(n, m) + 1):
        for rows in itertools.combinations(range(n), k):
            for cols in itertools.permutations(range(m), k):
                value = sum(score[r, c] for r, c in zip(rows, cols)) + slack / 2 * ((n - k) + (m - k))
                best = max(best, value)
    return best


def test_slack_matches_brute_force():
    rng = np.random.default_rng(2)
    for _ in range(40):
        n, m = rng.integers(1, 5, size=2)
        score = rng.normal(size=(n, m))
        slack = float(rng.normal())
        sol = linear_assignment(score, slack=slack)
        matched = sol >= 0
        value = assignment_score(score, sol) + slack / 2 * ((n - matched.sum()) + (m - matched.sum()))
        assert value == pytest.approx(brute_force_partial(score, slack), abs=1e-8)
    assert list(linear_assignment(np.array([[5.0, 0.0], [0.0, 1.0]]), slack=2.0)) == [0, -1]
    # larger instances against scipy on the textbook padding: one dummy row per column, one dummy column per
    # row, each worth slack/2, dummy pairs worth 0
    for n, m, dtype in ((60, 90, np.float64), (90, 60, np.float64), (70, 70, np.float32), (40, 45, np.float64)):
        score = rng.normal(size=(n, m)).astype(dtype)
        if dtype == np.float64 and n == 40:
            score = np.round(score)  # ties
        slack = float(np.quantile(score.max(axis=1), 0.3))
        padded = np.zeros((n + m, n + m))
        padded[:n, :m] = score
        padded[:n, m:] = padded[n:, :m] = slack / 2
        sol = linear_assignment(score, slack=slack)
        matched = sol >= 0
        assert np.unique(sol[matched]).size == matched.sum()
        value = assignment_score(score, sol) + slack / 2 * ((n - matched.sum()) + (m - matched.sum()))
        assert value == pytest.approx(exact_value(padded), abs=1e-6 * float(np.ptp(score)))
        assert np.all(score[matched, sol[matched]] >= slack - 1e-6)


def test_rectangular_matches_scipy_and_warm_start():
    rng = np.random.default_rng(3)
    score = rng.random((30, 50))
    sol = linear_assignment(score)
    assert assignment_score(score, sol) == pytest.approx(exact_value(score), abs=1e-9)
    wide = linear_assignment(score.T)
    assert (wide >= 0).sum() == 30
    prices = np.zeros(50)
    first = linear_assignment(rng.random((50, 50)), prices=prices)
    assert first.shape == (50,) and prices.max() > 0
    second_score = rng.random((50, 50))
    warm = linear_assignment(second_score, prices=prices)
    assert assignment_score(second_score, warm) == pytest.approx(exact_value(second_score), abs=1e-8)


def test_duality_gap_is_the_lp_gap():
    # Σ_i max_j (s_ij − p_j) + Σ_j p_j is the dual objective at prices p, Σ_i s_iσ(i) the primal at σ: their
    # difference bounds σ's suboptimality, and it is zero exactly for optimal prices with an optimal σ
    from corrlib.assignment import _duality_gap

    rng = np.random.default_rng(11)
    for n in (1, 2, 5, 9):
        score = rng.normal(size=(n, n))
        prices = rng.normal(size=n)
        sigma = rng.permutation(n)
        dual = sum(max(score[i, j] - prices[j] for j in range(n)) for i in range(n)) + prices.sum()
        primal = sum(score[i, sigma[i]] for i in range(n))
        assert _duality_gap(score, prices, sigma) == pytest.approx(dual - primal, abs=1e-12)
        assert dual >= exact_value(score) - 1e-12 >= primal - 1e-12  # weak duality, on every instance
        optimum = linear_assignment(score, method="scipy")
        # prices of the exact dual (SciPy's assignment is optimal; LP prices from the auction at a tiny ε)
        auction_prices = np.zeros(n)
        linear_assignment(score, prices=auction_prices, eps_final=1e-13)
        assert _duality_gap(score, auction_prices, optimum) <= n * 1e-12 + 1e-12


def test_a_warm_map_sets_the_first_eps_and_keeps_the_optimum(monkeypatch):
    # a DC-like sequence: each problem a perturbation of the last, solved from the last prices and solution
    import corrlib.assignment as assignment

    first_eps = []
    auction = assignment._auction

    def recording(benefit, benefit_t, eps_start, *args):
        first_eps.append(eps_start)
        return auction(benefit, benefit_t, eps_start, *args)

    monkeypatch.setattr(assignment, "_auction", recording)
    rng = np.random.default_rng(5)
    base = rng.random((120, 120))
    prices, previous = np.zeros(120), None
    for step in range(6):
        score = base + rng.normal(scale=10.0 ** -step, size=base.shape)  # from very different to nearly equal
        before = prices.copy()
        sol = linear_assignment(score, prices=prices, warm_map=previous)
        assert assignment_score(score, sol) == pytest.approx(exact_value(score), abs=1e-7)
        span = float(score.max() - score.min())
        if previous is None:  # cold prices: the auction's own start, a quarter of the range
            assert first_eps[-1] == pytest.approx(0.25 * span)
        else:  # the warm state's duality gap per row, brute force
            gap = np.max(score - before[None, :], axis=1).sum() + before.sum() - score[np.arange(120), previous].sum()
            assert first_eps[-1] == pytest.approx(min(max(gap / 120, 1e-12 * span), 0.25 * span), rel=1e-9)
        previous = sol
    # from very different problems the start is coarse, from nearly equal ones fine
    assert first_eps[1] > 100 * first_eps[-1]
    with pytest.raises(InputError, match="warm_map must be a permutation"):
        linear_assignment(base, prices=prices, warm_map=np.zeros(120, dtype=int))
    with pytest.raises(InputError, match="warm_map must be a permutation"):
        linear_assignment(base, prices=prices, warm_map=np.arange(119))
    # rectangular, slack or capacities: the warm map is not read (the gap is that of a square assignment)
    wide = rng.random((40, 60))
    sol = linear_assignment(wide, prices=np.zeros(60), warm_map=np.arange(40))
    assert assignment_score(wide, sol) == pytest.approx(exact_value(wide), abs=1e-8)


def test_assignment_errors():
    with pytest.raises(InputError, match="NaN"):
        linear_assignment(np.array([[np.nan, 1.0], [0.0, 1.0]]))
    with pytest.raises(InputError, match="non-empty"):
        linear_assignment(np.zeros((0, 3)))
    with pytest.raises(ParameterError, match="unknown assignment method"):
        linear_assignment(np.eye(3), method="hungarian-magic")
    with pytest.raises(InputError, match="slack must be a finite number"):
        linear_assignment(np.eye(3), slack=float("nan"))
    with pytest.raises(ParameterError, match="eps_start must lie in"):
        linear_assignment(np.eye(3), eps_start=2.0)
    with pytest.raises(ParameterError, match="eps_final must be positive"):
        linear_assignment(np.eye(3), eps_final=-1.0)
    for bad in (float("nan"), float("inf")):  # NaN used to loop forever
        with pytest.raises(ParameterError, match="eps_final must be positive and finite"):
            linear_assignment(np.random.default_rng(1).random((5, 5)), eps_final=bad)
        with pytest.raises(ParameterError, match="eps_start must lie in"):
            linear_assignment(np.random.default_rng(1).random((5, 5)), eps_start=bad)
    flag = np.ones(1, dtype=np.int8)
    with pytest.raises(Cancelled):
        linear_assignment(np.random.default_rng(0).random((20, 20)), cancel=flag)
    assert list(linear_assignment(np.eye(3), method="scipy")) == [0, 1, 2]


def brute_force_capacitated(score, capacity):
    """Best map of rows to columns with at most capacity[j] rows on column j (every row matched)."""
    n_rows, n_cols = score.shape
    best = -np.inf
    for cols in itertools.product(range(n_cols), repeat=n_rows):
        if np.all(np.bincount(cols, minlength=n_cols) <= capacity):
            best = max(best, float(score[np.arange(n_rows), cols].sum()))
    return best


def test_capacities_equal_brute_force_and_replicated_columns():
    rng = np.random.default_rng(7)
    for trial in range(60):
        n_rows, n_cols = int(rng.integers(1, 6)), int(rng.integers(1, 5))
        capacity = rng.integers(1, 4, n_cols)
        if capacity.sum() < n_rows:
            capacity[0] += n_rows - capacity.sum()
        score = rng.normal(size=(n_rows, n_cols))
        sol = linear_assignment(score, capacity=capacity)
        assert np.all(sol >= 0) and np.all(np.bincount(sol, minlength=n_cols) <= capacity)
        assert assignment_score(score, sol) == pytest.approx(brute_force_capacitated(score, capacity), abs=1e-8)
    # larger instances: the optimum of scipy's exact solver on explicitly replicated columns
    for trial in range(20):
        n_rows, n_cols = int(rng.integers(50, 200)), int(rng.integers(30, 150))
        capacity = rng.integers(1, 4, n_cols)
        score = rng.normal(size=(n_rows, n_cols))
        copies = np.repeat(np.arange(n_cols), capacity)
        sol = linear_assignment(score, capacity=capacity)
        assert np.all(np.bincount(sol[sol >= 0], minlength=n_cols) <= capacity)
        assert (sol >= 0).sum() == min(n_rows, capacity.sum())
        assert assignment_score(score, sol) == pytest.approx(exact_value(score[:, copies]), abs=1e-8)


def test_capacity_errors():
    with pytest.raises(InputError, match="capacity must hold one integer >= 1 per column"):
        linear_assignment(np.zeros((3, 2)), capacity=np.array([1, 0]))
    with pytest.raises(InputError, match="capacity"):
        linear_assignment(np.zeros((3, 2)), capacity=np.array([1.5, 2.0]))


def test_ties_below_the_resolution_of_the_scores_terminate():
    # equal scores (zero range), and a tiny range on a huge offset: ε would fall below the floating-point
    # resolution, a bid would not move a price, and tied rows would outbid each other forever
    sol = linear_assignment(np.ones((4, 4)))
    assert sorted(sol) == [0, 1, 2, 3]
    assert sorted(linear_assignment(np.zeros((1, 1)), capacity=np.array([3]))) == [0]
    rng = np.random.default_rng(3)
    score = 1e12 + rng.integers(0, 3, size=(40, 40)).astype(float)
    sol = linear_assignment(score)
    assert assignment_score(score, sol) == pytest.approx(exact_value(score), rel=1e-15)


def test_asymmetric_auction_with_duplicate_columns_and_warm_prices():
    # rectangular problems run the reverse auction; duplicated columns (capacities) make long runs of ties
    # in the candidate lists; prices of another problem as a warm start must not change the optimum
    rng = np.random.default_rng(11)
    for trial in range(30):
        m = int(rng.integers(20, 120))
        base = rng.normal(size=(m, int(rng.integers(10, 80))))
        if trial % 2:  # smooth, kernel-like rows
            x = np.sort(rng.random(m))[:, None]
            y = np.sort(rng.random(base.shape[1]))[None, :]
            base = np.exp(-((x - y) ** 2) / 0.01)
        cols = rng.integers(0, base.shape[1], m + int(rng.integers(0, 3 * m)))
        score = base[:, cols]
        prices = rng.random(score.shape[1]) * np.ptp(score) if trial % 3 == 0 else None
        sol = linear_assignment(score, prices=prices)
        assert np.all(sol >= 0) and np.unique(sol).size == m
        assert abs(assignment_score(score, sol) - exact_value(score)) <= 1e-8 * np.ptp(score)
        tall = linear_assignment(np.ascontiguousarray(score.T))
        assert (tall >= 0).sum() == m
        assert abs(assignment_score(score.T, tall) - exact_value(score)) <= 1e-8 * np.ptp(score)


def test_a_price_war_hands_over_to_the_exact_solver(monkeypatch):
    """Copies of columns (capacities) on exactly tied scores: the auction's bids of ε can go on for minutes
    (measured: 192 s on one 682 × 1004 cell of kernel matching between a symmetric and a posed person, where
    scipy takes 0.17 s). With the bid budget spent at once the exact solver answers, with the optimum."""
    import corrlib.assignment as assignment

    rng = np.random.default_rng(3)
    half = rng.integers(0, 4, size=(60, 20)).astype(np.float64)
    score = np.hstack([half, half])  # every column has an exact twin
    capacity = rng.integers(2, 4, size=40)  # room for every row
    expected = linear_assignment(score, capacity=capacity, method="scipy")
    for budget in (assignment.BID_BUDGET, 1e-9):  # the auction, then the hand-over on the first bid
        monkeypatch.setattr(assignment, "BID_BUDGET", budget)
        got = linear_assignment(score, capacity=capacity)
        assert np.all(got >= 0) and np.all(np.bincount(got, minlength=40) <= capacity)
        assert assignment_score(score, got) == pytest.approx(assignment_score(score, expected))


def test_float32_scores_are_solved_to_their_own_precision():
    """The auction stops at the scores' precision: the gap to the exact optimum of the float32 values is at most
    ``m · eps32 · max |s|``, the order of the objective's own rounding; float64 scores keep 1e-9 of the range."""
    rng = np.random.default_rng(3)
    eps32 = float(np.finfo(np.float32).eps)
    for n in (50, 200, 400):
        base = rng.normal(size=(n, 20)) @ rng.normal(size=(20, n))  # smooth, near-tied like kernel scores
        s32 = base.astype(np.float32)
        gap = exact_value(s32.astype(np.float64)) - assignment_score(s32, linear_assignment(s32))
        assert -1e-9 <= gap <= n * eps32 * float(np.abs(s32).max())
        gap64 = exact_value(base) - assignment_score(base, linear_assignment(base))
        assert -1e-9 <= gap64 <= 1e-8 * np.ptp(base)
