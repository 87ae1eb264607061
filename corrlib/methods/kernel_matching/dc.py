"""The DC algorithm on the seeds (Eq. 8.13): the seed problem (:class:`SeedProblem`), its objective
(:func:`dc_objective`) and linearised score (:func:`seed_score`), and one DC step (:func:`dc_step`, a linear
assignment of the linearisation, which never lowers the convex objective).
"""

from __future__ import annotations

from dataclasses import dataclass
import functools

import numpy as np

from corrlib.assignment import linear_assignment
from corrlib.methods.kernel_matching.scores import alignment, kernel_energy, kernel_score
from corrlib.progress import Stopwatch


#: a DC step that lowers the objective by more than this fraction of it clears the ``monotone`` flag (the
#: auction is ε-optimal and the score is float32)
MONOTONE_RTOL = 1e-5


@dataclass(frozen=True)
class SeedProblem:
    """The quadratic assignment on the seeds, without its diffusion time.

    Attributes
    ----------
    phi_s : (n_seed, k) float
        Source eigenfunctions Φ at the source seeds.
    psi_s : (n_seed, k) float
        Target eigenfunctions Ψ at the target seeds.
    anchor_c : (k, k) float or 0.0
        Alignment ``Ψ[anchors_y]ᵀ Φ[anchors_x]`` of fixed matches (landmarks), added to every ``C``.
    desc_block : (n_seed, n_seed) float32 or None
        Descriptor similarity ``F_Y F_Xᵀ`` as (seed x, seed y), scaled to [-1, 0]; None without μ term.
    mu : float
        Weight μ of the descriptor term.
    free_x, free_y : (f,) int and (g,) int, or None
        With landmarks: the x seeds the assignments place (the others are fixed at a landmark's partner,
        :func:`~.seed_stage.fixed_seeds`) and the y seeds not taken by a fixed one, ``f ≤ g``; None: every seed.
    """

    phi_s: np.ndarray
    psi_s: np.ndarray
    anchor_c: np.ndarray | float
    desc_block: np.ndarray | None
    mu: float
    free_x: np.ndarray | None = None
    free_y: np.ndarray | None = None

    @functools.cached_property
    def free_blocks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """``Φ_s``, ``Ψ_s`` and the descriptor block on the free seeds only (the assignment's rows and
        columns), formed once per problem: the whole problem's arrays when every seed is free."""
        if self.free_x is None:
            return self.phi_s, self.psi_s, self.desc_block
        desc = None if self.desc_block is None else self.desc_block[np.ix_(self.free_x, self.free_y)]
        return self.phi_s[self.free_x], self.psi_s[self.free_y], desc

    @functools.cached_property
    def free_column(self) -> np.ndarray | None:
        """(n_seed,) int: the assignment column of every y seed that is free, -1 for the others; None when every
        seed is free (the column is the seed)."""
        if self.free_y is None:
            return None
        column = np.full(self.psi_s.shape[0], -1, dtype=np.int64)
        column[self.free_y] = np.arange(self.free_y.size)
        return column

    @property
    def n_columns(self) -> int:
        """Columns of the seed assignment (the size of its auction prices)."""
        return self.psi_s.shape[0] if self.free_y is None else self.free_y.size


def free_assignment(problem: SeedProblem, seed_map: np.ndarray, score: np.ndarray, **auction) -> np.ndarray:
    """(n_seed,) int: ``seed_map`` with its free seeds placed by one linear assignment on ``score`` (free x seeds,
    free y seeds), :func:`~corrlib.assignment.linear_assignment` with ``auction``'s arguments; the whole map
    when every seed is free."""
    warm = warm_columns(problem, seed_map)
    if problem.free_x is None:
        return linear_assignment(score, warm_map=warm, **auction)
    placed = seed_map.copy()
    if problem.free_x.size:
        placed[problem.free_x] = problem.free_y[linear_assignment(score, warm_map=warm, **auction)]
    return placed


def warm_columns(problem: SeedProblem, seed_map: np.ndarray) -> np.ndarray | None:
    """The columns of the seed assignment that ``seed_map`` (n_seed,) gives its free seeds, if that is a
    permutation of them (the warm start of the next auction, see
    :func:`~corrlib.assignment.linear_assignment`'s ``warm_map``); None otherwise (e.g. a given map that sends
    seeds together)."""
    columns = seed_map if problem.free_x is None else problem.free_column[seed_map[problem.free_x]]
    if columns.size != problem.n_columns or not np.array_equal(np.sort(columns), np.arange(columns.size)):
        return None
    return columns


def seed_alignment(problem: SeedProblem, seed_map: np.ndarray) -> np.ndarray:
    """(k, k) float: ``C = Ψ_s[seed_map]ᵀ Φ_s + C_anchors``, the spectral form of Π (and the anchors)."""
    return alignment(problem.psi_s[seed_map], problem.phi_s) + problem.anchor_c


def updated_alignment(problem: SeedProblem, c: np.ndarray, old_map: np.ndarray, new_map: np.ndarray) -> np.ndarray:
    """(k, k) float: :func:`seed_alignment` of ``new_map`` from ``c``, that of ``old_map`` (both (n_seed,)).

    ``C`` is a sum over the seeds, so only the changed seeds' terms are exchanged:
    ``C' = C + (Ψ_s[new_map[ch]] − Ψ_s[old_map[ch]])ᵀ Φ_s[ch]``, at a cost proportional to the changed seeds (the
    later DC steps change a few per cent). Where half or more changed, ``C'`` is formed afresh. Equal to the
    direct product up to round-off.
    """
    changed = np.flatnonzero(new_map != old_map)
    if changed.size == 0:
        return c
    if 2 * changed.size >= new_map.size:
        return seed_alignment(problem, new_map)
    return c + alignment(problem.psi_s[new_map[changed]] - problem.psi_s[old_map[changed]], problem.phi_s[changed])


def dc_objective(seed_map: np.ndarray, c: np.ndarray, kernel_scale: float, decay_y: np.ndarray,
                 decay_x: np.ndarray, desc_block: np.ndarray | None = None, mu: float = 0.0) -> float:
    """The function the DC steps of one time maximise.

    ``f(Π) = ½ <Π, K_Y Π K_X> / s + μ <Π, F_Y F_Xᵀ>``, the kernel term in spectral form
    ``<Π, K_Y Π K_X> = trace(D_Y C D_X Cᵀ)`` (:func:`~.scores.kernel_energy`) and ``s`` a constant of the time (the
    kernel score's maximum, see :func:`seed_score`). The ½ makes ``K_Y Π K_X / s`` its exact gradient.

    Parameters
    ----------
    seed_map : (n_seed,) int
        Seed x -> seed y (Π).
    c : (k, k) float
        ``Ψ_s[seed_map]ᵀ Φ_s`` (plus the anchors), see :func:`seed_alignment`.
    kernel_scale : float
        ``s``.
    decay_y, decay_x : (k,) float
        ``e^{-tΛ_Y}``, ``e^{-tΛ_X}``.
    desc_block : (n_seed, n_seed) float32, optional
        ``F_Y F_Xᵀ`` as (seed x, seed y); None: no descriptor term.
    mu : float
        μ.
    """
    value = 0.5 * kernel_energy(c, decay_y, decay_x) / kernel_scale
    if desc_block is not None:
        value += mu * float(desc_block[np.arange(seed_map.size), seed_map].sum())
    return value


def seed_score(phi_s: np.ndarray, psi_s: np.ndarray, c: np.ndarray, decay_y: np.ndarray, decay_x: np.ndarray,
               kernel_scale: float | None = None, desc_block: np.ndarray | None = None,
               mu: float = 0.0) -> tuple[np.ndarray, float]:
    """The linearisation (Eq. 8.13) of :func:`dc_objective` on the seeds, as an assignment score.

    ``G = (K_Y Π K_X)ᵀ / s + μ (F_Y F_Xᵀ)ᵀ``, rows the x seeds, formed in spectral form as
    ``(Φ_s D_X) Cᵀ (Ψ_s D_Y)ᵀ / s + μ desc_block`` (:func:`~.scores.kernel_score`, float32).

    Parameters
    ----------
    phi_s, psi_s : (n_seed, k) float
        Eigenfunctions at the source and target seeds.
    c : (k, k) float
        Current alignment ``C``.
    decay_y, decay_x : (k,) float
        ``e^{-tΛ_Y}``, ``e^{-tΛ_X}``.
    kernel_scale : float, optional
        ``s``; None: the kernel term's own largest magnitude.
    desc_block : (n_seed, n_seed) float32, optional
        ``F`` as (seed x, seed y); None: the kernel term alone, unscaled.
    mu : float
        μ.

    Returns
    -------
    g : (n_seed, n_seed) float32
        Score (seed x, seed y).
    kernel_scale : float
        ``s`` (as given, or the one found).
    """
    g = kernel_score(phi_s, psi_s, c.T, decay_x, decay_y)  # the assignment's rows are the x seeds
    if kernel_scale is None:
        kernel_scale = max(float(np.abs(g).max(initial=0.0)), 1e-30)
    if desc_block is not None:
        g = g / np.float32(kernel_scale) + np.float32(mu) * desc_block
    return g, kernel_scale


@dataclass(frozen=True)
class DCStep:
    """One DC step: the new map, its alignment ``C`` (:func:`seed_alignment`) and the objective before and after
    (same ``kernel_scale``)."""

    seed_map: np.ndarray
    before: float
    value: float
    changed: int
    kernel_scale: float
    from_permutation: bool
    alignment: np.ndarray

    @property
    def decreased(self) -> bool:
        """The objective fell (beyond :data:`MONOTONE_RTOL`) from a permutation, against the DC guarantee."""
        return self.from_permutation and self.value < self.before - MONOTONE_RTOL * abs(self.before)


def dc_step(problem: SeedProblem, seed_map: np.ndarray, decay_y: np.ndarray, decay_x: np.ndarray,
            kernel_scale: float | None = None, *, prices: np.ndarray | None = None,
            eps_start: float | None = None, backend: str = "auction", cancel: np.ndarray | None = None,
            watch: Stopwatch | None = None, alignment: np.ndarray | None = None) -> DCStep:
    """One DC step (Eq. 8.13): ``Π_{k+1} = argmax_Π <Π, ∇f(Π_k)>``, one linear assignment on :func:`seed_score`.

    ``f`` (:func:`dc_objective`) is convex, so ``f(Π_{k+1}) ≥ f(Π_k) + <Π_{k+1} - Π_k, ∇f(Π_k)> ≥ f(Π_k)``
    when ``Π_k`` is a permutation (the assignment's optimum is at least the score of ``Π_k`` itself). With
    seeds fixed by landmarks, the assignment places the free seeds only (:attr:`SeedProblem.free_blocks`): the
    maximum over the permutations that keep the fixed ones, among which ``Π_k`` is, so the same holds.

    Parameters
    ----------
    seed_map : (n_seed,) int
        ``Π_k``, seed x -> seed y.
    kernel_scale : float, optional
        ``s`` of the time; None: from this step's score.
    prices : (n_columns,) float, optional
        The auction's prices (warm start, :attr:`SeedProblem.n_columns`), updated in place.
    eps_start : float, optional
        The auction's first ε.
    alignment : (k, k) float, optional
        ``C`` of ``seed_map`` if known (the previous step's :attr:`DCStep.alignment`); None: formed here.
    """
    watch = Stopwatch() if watch is None else watch
    with watch("kernels"):
        c = seed_alignment(problem, seed_map) if alignment is None else alignment
        phi_rows, psi_cols, desc = problem.free_blocks
        g, kernel_scale = seed_score(phi_rows, psi_cols, c, decay_y, decay_x, kernel_scale, desc, problem.mu)
        before = dc_objective(seed_map, c, kernel_scale, decay_y, decay_x, problem.desc_block, problem.mu)
    with watch("assignment"):
        new_map = free_assignment(problem, seed_map, g, method=backend, cancel=cancel, prices=prices,
                                  eps_start=eps_start)
    changed = int(np.sum(new_map != seed_map))
    with watch("kernels"):
        c_new = updated_alignment(problem, c, seed_map, new_map)
    value = dc_objective(new_map, c_new, kernel_scale, decay_y, decay_x, problem.desc_block, problem.mu)
    # the DC guarantee holds from a permutation (a given initial map may map seeds together)
    from_permutation = np.unique(seed_map).size == seed_map.size
    return DCStep(new_map, before, value, changed, kernel_scale, from_permutation, c_new)
