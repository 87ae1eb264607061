"""Stages 2–5, on the seeds: the initial assignment (:func:`initial_seed_map`), the seed problem
(:func:`seed_problem`), the better of the initial and the aligned start at the first time
(:func:`choose_start`), and the DC iterations at each later time (:func:`dc_iterations`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from corrlib.assignment import linear_assignment
from corrlib.cores import InlineExecutor, side_threads
from corrlib.methods.base import InitialMatch
from corrlib.methods.kernel_matching.dc import SeedProblem, dc_step, free_assignment, seed_score
from corrlib.methods.kernel_matching.params import PROGRESS_DC, PROGRESS_INIT
from corrlib.methods.kernel_matching.scores import (alignment, descriptor_similarity, most_similar_matches,
                                                    shape_descriptors, with_orientation)
from corrlib.methods.kernel_matching.state import KernelState, nearest_point
from corrlib.progress import Progress, Stopwatch, run


def initial_seed_map(state: KernelState, initial: InitialMatch | None, compete: bool = True):
    """Stage 2: the seeds' initial assignment (sets ``seed_map``, and ``confidence`` or the anchors).

    A given map or landmarks: every source seed follows its nearest matched vertex, whose partner snaps to
    the nearest target seed (landmarks also become anchors). A given map competes with the method's own
    start, the descriptor assignment (``compete``; :func:`aligned_start`, :func:`choose_start`): a map given
    to be refined can be far worse than that start (a nearest-neighbour map of a non-isometric pair, 0.64
    √area), and its refinement then stays in a wrong basin. ``init="fmap"``: the same from the
    functional-maps baseline's map. Otherwise one linear assignment on the descriptor similarity
    (:func:`~.scores.descriptor_similarity`, with the orientation block), whose row values are the ``confidence``.
    A generator (yields :class:`Progress`).
    """
    params, source, target = state.params, state.source, state.target
    if initial is not None:
        ix, iy = initial.pairs(state.n_x, state.n_y)
        state.landmarks_only = initial.map_xy is None
        if state.landmarks_only:
            state.anchors_x, state.anchors_y = ix, iy
        yield Progress("initial map", PROGRESS_DC[0], f"{ix.size} given matches")
        if not state.landmarks_only:
            state.refined_map = (ix, iy)
            state.descriptor_start = state.outside_map = compete
        partner_of = -np.ones(state.n_x, dtype=np.int64)
        partner_of[ix] = iy
        if state.landmarks_only:
            state.seed_map, state.free_x, state.free_y = fixed_seeds(state, partner_of)
        else:
            partner = partner_of[ix[nearest_point(source.vertices[ix], state.seeds_x.points)]]
            state.seed_map = nearest_point(state.seeds_y.points, target.vertices[partner])
    elif params.init == "fmap":
        from corrlib.methods.baselines import FmapZoomOutParams, solve_fmap_zoomout

        yield Progress("initial map", PROGRESS_INIT, "functional maps + ZoomOut")
        with state.watch("init"):
            fm = run(solve_fmap_zoomout(source, target, FmapZoomOutParams(), state.token))
        state.refined_map, state.outside_map = (np.arange(state.n_x), fm.map_xy), True
        partner = fm.map_xy[state.seeds_x.nearest_corners(source)]
        state.seed_map = nearest_point(state.seeds_y.points, target.vertices[partner])
    else:
        yield Progress("descriptors", PROGRESS_INIT, params.descriptor)
        state.descriptors()
        state.seed_map, state.confidence = descriptor_assignment(state, state.watch)
    state.token.raise_if_cancelled()


def fixed_seeds(state: KernelState, partner_of: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The seeds that landmarks fix: every x seed whose nearest vertex is a landmark is matched to the y seed
    nearest to that landmark's partner (of several x seeds that snap to one y seed, the first keeps it).

    Landmarks stay matched (:class:`~corrlib.methods.base.InitialMatch`), so the assignments only place the
    other seeds, on the y seeds the fixed ones leave (the placed seeds of a release pass are the released
    limbs: the problem shrinks to them).

    Parameters
    ----------
    partner_of : (n_x,) int
        The landmark partner of every source vertex, -1 where it is no landmark.

    Returns
    -------
    seed_map : (n_seed,) int
        The fixed seeds' partners, -1 for the free ones.
    free_x, free_y : (f,) int
        The free x seeds and the y seeds no fixed seed takes (as many).
    """
    source, target = state.source, state.target
    partner = partner_of[state.seeds_x.nearest_corners(source)]
    fixed = np.flatnonzero(partner >= 0)
    snapped = nearest_point(state.seeds_y.points, target.vertices[partner[fixed]])
    _, first = np.unique(snapped, return_index=True)
    seed_map = -np.ones(state.n_seed, dtype=np.int64)
    seed_map[fixed[first]] = snapped[first]
    taken = np.zeros(state.n_seed, dtype=bool)
    taken[seed_map[seed_map >= 0]] = True
    return seed_map, np.flatnonzero(seed_map < 0), np.flatnonzero(~taken)


def seed_problem(state: KernelState) -> SeedProblem:
    """Stage 3: the :class:`~.dc.SeedProblem` — eigenfunctions interpolated at the seeds, ``F_Y F_Xᵀ`` of the plain
    descriptor (the orientation block only decides the initial orientation), the anchors' ``C``."""
    params, source, target = state.params, state.source, state.target
    psi_s = state.seeds_y.interpolate(target, state.psi)
    phi_s = state.seeds_x.interpolate(source, state.phi)
    desc_block = state.seed_descriptor_similarity() if params.mu > 0 else None  # (seed x, seed y)
    anchor_c = alignment(state.psi[state.anchors_y], state.phi[state.anchors_x]) if state.anchors_x.size else 0.0
    state.problem = SeedProblem(phi_s, psi_s, anchor_c, desc_block, params.mu, state.free_x, state.free_y)
    return state.problem


@dataclass(frozen=True)
class DCRun:
    """DC iterations at one time: the last map and its alignment ``C``, the time's kernel scale, one trace
    entry per iteration and the last objective."""

    seed_map: np.ndarray
    kernel_scale: float
    entries: list
    value: float | None
    alignment: np.ndarray | None = None


def dc_iterations(state: KernelState, seed_map: np.ndarray, prices: np.ndarray, t_index: int,
                  kernel_scale: float | None = None, alignment: np.ndarray | None = None):
    """Stage 5: up to ``iters_per_time`` :func:`~.dc.dc_step` at the time ``taus[t_index]``; stops when the map
    no longer changes.

    A generator (yields :class:`Progress`); returns a :class:`DCRun`. ``prices`` (the auction's warm start) is
    updated in place (each auction's first ε follows from how far they are from ``seed_map``'s score,
    :func:`~.dc.warm_columns`); ``kernel_scale`` None: set from the first score; ``alignment``: ``C`` of ``seed_map`` if
    known (it does not depend on the time, so it is carried from one time to the next). Clears
    ``state.monotone`` if a step lowers the objective.
    """
    params = state.params
    tau = state.taus[t_index]
    decay_y, decay_x = state.decays(tau)
    entries, value = [], None
    for it in range(params.iters_per_time):
        state.token.raise_if_cancelled()
        step = dc_step(state.problem, seed_map, decay_y, decay_x, kernel_scale, prices=prices, backend=params.backend,
                       cancel=state.cancel, watch=state.watch, alignment=alignment)
        kernel_scale, value, seed_map, alignment = step.kernel_scale, step.value, step.seed_map, step.alignment
        if step.decreased:
            state.monotone = False
        entries.append({"tau": float(tau), "iteration": it, "energy": value, "changed": step.changed})
        state.step += 1
        yield Progress("kernel matching", PROGRESS_DC[0] + PROGRESS_DC[1] * state.step / state.total_steps,
                       f"time {t_index + 1}/{len(state.taus)}, iteration {it + 1}: energy {value:.6g}, "
                       f"{step.changed} changed")
        if step.changed == 0:
            state.step += params.iters_per_time - it - 1
            break
    return DCRun(seed_map, kernel_scale, entries, value, alignment)


def aligned_start(state: KernelState, start_map: np.ndarray, watch: Stopwatch) -> tuple[np.ndarray, np.ndarray]:
    """The second start: one assignment on the kernel score at the largest time of only the most similar
    initial matches (``init_fraction`` of them; with landmarks: the anchors alone), i.e. ``G`` of
    :func:`~.dc.seed_score` with ``C = Ψ_s[start_map[keep]]ᵀ Φ_s[keep] + C_anchors``.

    A given map's second start is instead the descriptor assignment of the descriptor initialisation
    (:func:`descriptor_assignment`).

    Reads ``state`` only (it runs on a thread beside the first start's DC iterations) and times itself on
    ``watch``. Returns the start map (n_seed,) and its auction prices (:attr:`SeedProblem.n_columns`,).
    With landmarks it is the only start (:func:`choose_start`) and places the free seeds only.
    """
    if state.descriptor_start:
        return descriptor_assignment(state, watch)[0], np.zeros(state.n_seed)
    problem = state.problem
    keep = np.zeros(0, dtype=np.int64) if state.landmarks_only else \
        most_similar_matches(state.confidence, state.params.init_fraction)
    with watch("kernels"):
        c = alignment(problem.psi_s[start_map[keep]], problem.phi_s[keep]) + problem.anchor_c
        phi_rows, psi_cols, desc = problem.free_blocks
        g, _ = seed_score(phi_rows, psi_cols, c, *state.decays(state.taus[0]), None, desc, problem.mu)
    prices = np.zeros(problem.n_columns)
    with watch("assignment"):
        other_start = free_assignment(problem, start_map, g, method=state.params.backend, cancel=state.cancel,
                                      prices=prices)
    return other_start, prices


def descriptor_assignment(state: KernelState, watch: Stopwatch) -> tuple[np.ndarray, np.ndarray]:
    """The descriptor initialisation's start: one linear assignment of the seeds on the similarity of their
    descriptors with the orientation block (:func:`~.scores.descriptor_similarity`). Returns the seed map (n_seed,)
    and every match's similarity (n_seed,). Reads ``state`` only (the descriptors of :func:`seed_problem` when
    it computed them)."""
    params, source, target = state.params, state.source, state.target
    with watch("descriptors"):
        desc_x, desc_y = (state.desc_x, state.desc_y) if state.desc_x is not None else \
            shape_descriptors(source, target, state.spec_x, state.spec_y, params.descriptor)
        init_x, init_y = with_orientation(desc_x, desc_y, *state.orientation_blocks(), params.orientation)
    with watch("assignment"):
        sim = descriptor_similarity(state.seeds_x.interpolate(source, init_x),
                                     state.seeds_y.interpolate(target, init_y))
        seed_map = linear_assignment(sim, method=params.backend, cancel=state.cancel)
    return seed_map, sim[np.arange(state.n_seed), seed_map]


def choose_start(state: KernelState):
    """Stage 4: DC iterations of the first time from the initial map and (descriptor initialisation, or a
    given map) from the :func:`aligned_start`; the start with the higher :func:`~.dc.dc_objective` goes on (both at
    the first start's kernel scale). A generator; sets ``seed_map``, ``prices``, ``dc_start``.

    The aligned start's score and assignment do not depend on the first start's iterations, so they run on
    a thread beside them (the auctions release the GIL; two cores each take one); their time is reported
    as ``"second start (concurrent)"``. A pool's worker with one core's share runs them first instead
    (:func:`~corrlib.cores.side_threads`), reported as ``"second start"``.

    Landmarks have the aligned start only (the kernel score of the landmarks alone): the seeds they do not fix
    have no partner of their own to start from (:func:`fixed_seeds`).
    """
    if state.landmarks_only:
        yield Progress("initial alignment", PROGRESS_DC[0], f"kernel score of the {state.anchors_x.size} landmarks")
        start_map, prices = aligned_start(state, state.seed_map, state.watch)
        best = yield from dc_iterations(state, start_map, prices, 0, None)
        dc_start = "initial alignment"
    else:
        best, prices, dc_start = yield from _better_of_two_starts(state)
    state.seed_map, state.prices, state.dc_start = best.seed_map, prices, dc_start
    state.start_alignment = best.alignment
    state.trace.extend(best.entries)


def _better_of_two_starts(state: KernelState):
    """:func:`choose_start` without landmarks: the initial map's first time and, beside it, the
    :func:`aligned_start`'s; returns the better :class:`DCRun`, its auction prices and the start's name."""
    prices = np.zeros(state.problem.n_columns)  # auction prices carried from one assignment to the next
    start_map = state.seed_map
    with side_threads(1) as pool:
        second_watch = Stopwatch()
        second = pool.submit(aligned_start, state, start_map, second_watch) if state.has_second_start else None
        best = yield from dc_iterations(state, start_map, prices, 0, None)
        dc_start = "initial map"
        if second is not None:
            what = ("descriptor assignment, against the given map" if state.descriptor_start else
                    f"kernel score of the most similar {state.params.init_fraction:.0%} of the initial matches")
            yield Progress("initial alignment", PROGRESS_DC[0] + PROGRESS_DC[1] * state.step / state.total_steps, what)
            other_start, other_prices = second.result()
            concurrent = not isinstance(pool, InlineExecutor)
            state.watch.times["second start (concurrent)" if concurrent else "second start"] = \
                sum(second_watch.times.values())
            other = yield from dc_iterations(state, other_start, other_prices, 0, best.kernel_scale)
            if other.value > best.value:
                best, prices = other, other_prices
                dc_start = "descriptors" if state.descriptor_start else "initial alignment"
    return best, prices, dc_start
