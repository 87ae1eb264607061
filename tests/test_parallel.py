"""Local parallelism: the core share of a pool's workers, and side threads that follow it."""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from corrlib import cores, parallel
from corrlib.methods import solve


def test_inline_executor_submits_at_once_maps_lazily_and_hands_exceptions_to_result():
    calls = []
    with cores.InlineExecutor() as pool:
        future = pool.submit(lambda a, b: calls.append((a, b)) or a + b, 2, b=3)
        assert future.done() and calls == [(2, 3)]  # ran before submit returned
        assert future.result() == 5
        failed = pool.submit(lambda: 1 / 0)
        assert failed.done()
        with pytest.raises(ZeroDivisionError):
            failed.result()
        calls.clear()
        squares = pool.map(lambda v: calls.append(v) or v * v, [3, 1, 2])
        assert calls == []  # lazily: a result is computed when it is asked for, not all of them first
        assert next(squares) == 9 and calls == [3]
        assert list(squares) == [1, 4]  # in order


def test_side_threads_are_threads_only_with_more_than_one_core(monkeypatch):
    monkeypatch.setattr(cores, "_core_share", 1)
    assert cores.core_share() == 1
    assert isinstance(cores.side_threads(2), cores.InlineExecutor)
    monkeypatch.setattr(cores, "_core_share", 2)
    with cores.side_threads(2) as pool:
        assert isinstance(pool, ThreadPoolExecutor) and pool._max_workers == 2
    monkeypatch.setattr(cores, "_core_share", None)  # outside a pool: every core of the machine
    assert cores.core_share() == (os.cpu_count() or 1)


@pytest.mark.parametrize("jobs", [1, 2, 64])
def test_pool_workers_know_their_share_of_the_cores(jobs):
    with parallel.process_pool(jobs) as pool:
        share = pool.submit(cores.core_share).result()
    assert share == max(1, (os.cpu_count() or 1) // jobs)  # never 0, even with more workers than cores


def test_a_pool_worker_can_be_limited_to_one_core():
    """``corr perf bench``'s serial baseline: one worker with one core's share, whatever the machine."""
    import numba

    with parallel.process_pool(1, share=1) as pool:
        assert pool.submit(cores.core_share).result() == 1
        assert pool.submit(numba.get_num_threads).result() == 1
        assert isinstance(pool.submit(cores.side_threads, 2).result(), cores.InlineExecutor)


def test_kernel_matching_in_a_one_core_worker_gives_the_same_map(wolf_pair, monkeypatch):
    """With one core's share the side work (samples, the aligned second start, the cells, and the functional
    map's start of init="best") runs in the calling thread instead of beside it: the same computations in
    another order, so the same map (and the same start kept)."""
    fast = dict(n_eigs=150, n_seeds=800, n_times=5, iters_per_time=2)
    threaded = solve("kernel-matching", *wolf_pair, **fast)
    monkeypatch.setattr(cores, "_core_share", 1)
    fractions = []
    inline = solve("kernel-matching", *wolf_pair, callback=lambda report: fractions.append(report.fraction), **fast)
    known = [f for f in fractions if f >= 0]  # one start after the other: the bar never goes back
    assert known[-1] == 1.0 and np.all(np.diff(known) >= -1e-12)
    np.testing.assert_array_equal(inline.map_xy, threaded.map_xy)
    # the same sums; side by side, BLAS has one thread, so their order (and the last bit) can differ
    assert inline.energy == pytest.approx(threaded.energy, rel=1e-12)
    assert inline.extras["init"] == threaded.extras["init"]
    for start, measures in threaded.extras["start_measures"].items():
        assert inline.extras["start_measures"][start] == pytest.approx(measures, rel=1e-12)
    assert "second start" in inline.timings and "second start (concurrent)" not in inline.timings


def test_a_worker_with_one_core_decomposes_both_shapes_itself(monkeypatch):
    """The eigensolver's second process is one more busy core: not where the process has one core's share."""
    from corrlib.geometry import spectrum

    monkeypatch.setattr(cores, "_core_share", 1)
    assert not spectrum._second_process_allowed()
    monkeypatch.setattr(cores, "_core_share", 2)
    assert spectrum._second_process_allowed()  # the test process is no pool's child


def test_a_cancelled_run_stops_its_workers_instead_of_waiting_for_their_jobs():
    """A user's cancel (``Cancelled``) ends the pool at once: its running jobs are not waited for (before, a
    cancelled retrieval in the studio waited for every mesh in progress)."""
    import time

    from corrlib.errors import Cancelled

    started = time.perf_counter()
    with pytest.raises(Cancelled):
        with parallel.job_executor(2, None) as pool:
            for _ in range(2):
                pool.submit(time.sleep, 60)
            workers = list(pool._processes.values())
            raise Cancelled("cancelled")
    assert time.perf_counter() - started < 30  # 60 s if the sleeping jobs were waited for
    assert workers
    for worker in workers:  # (the running jobs' futures may stay "running" for good: their workers are gone)
        worker.join(timeout=10)
        assert not worker.is_alive()


def test_an_error_of_the_caller_still_waits_for_the_running_jobs():
    """Any other error leaves the pool to finish its running jobs (their results may be written), as before."""
    import time

    with pytest.raises(RuntimeError):
        with parallel.job_executor(1, None) as pool:
            job = pool.submit(time.sleep, 0.5)
            raise RuntimeError("the caller's own error")
    assert job.done() and job.exception() is None


@pytest.mark.slow
def test_a_cancelled_run_on_a_dask_cluster_cancels_its_futures():
    """On a Dask cluster the user's cancel cancels the submitted futures (Dask's executor with ``wait=False``)
    instead of waiting for them, as the local pool stops its workers."""
    import time

    import distributed  # the dist extra is part of the test setup (scripts/test.sh)

    from corrlib.errors import Cancelled

    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        started = time.perf_counter()
        with pytest.raises(Cancelled):
            with parallel.job_executor(None, cluster.scheduler_address) as pool:
                jobs = [pool.submit(time.sleep, 30) for _ in range(3)]
                raise Cancelled("cancelled")
        assert time.perf_counter() - started < 20  # 90 s if the three sleeps were waited for
        assert all(job.cancelled() for job in jobs)


def test_the_threaded_kernels_give_the_same_result_on_one_thread_and_on_two(wolf_pair):
    """Every ``prange`` kernel of the library, on one numba thread and on two, bit for bit.

    Each kernel's iterations write their own rows, so the split of the rows between threads must not change
    a digit: a result never depends on the machine's cores or on the thread a job runs on.
    """
    import numba

    from corrlib.deformation.basis import DivFreeBasis
    from corrlib.deformation.flow import flow_with_jacobian, velocity
    from corrlib.deformation.mixture import mixture_moments
    from corrlib.descriptors.shot import shot
    from corrlib.methods.contour3d import feature_distances

    wolf = wolf_pair[0]
    rng = np.random.default_rng(5)
    basis = DivFreeBasis(300)
    coeffs = basis.random_coefficients(0.3, seed=4)
    points = rng.uniform(0.1, 0.9, (257, 3))  # not a multiple of the thread count
    targets = rng.uniform(0.1, 0.9, (301, 3))
    feats = rng.uniform(0, 1, (257, 301))

    def outputs():
        return [velocity(basis, points, coeffs), *flow_with_jacobian(basis, points, coeffs, n_steps=4),
                *flow_with_jacobian(basis, points, coeffs, n_steps=4, dtype=np.float32),
                *mixture_moments(points, targets, 0.01, 0.1), *mixture_moments(points, targets, 0.01, 0.0, feats),
                shot(wolf.vertices, wolf.faces), feature_distances(feats[:40, :60], feats[40:90, :60])]

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.fail("numba is limited to one thread (NUMBA_NUM_THREADS); this test compares one thread with two")
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        alone = outputs()
        numba.set_num_threads(2)
        together = outputs()
    finally:
        numba.set_num_threads(threads)
    for one, two in zip(alone, together):
        assert one.dtype == two.dtype and np.array_equal(one, two)
