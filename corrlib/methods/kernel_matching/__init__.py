"""Kernel matching (thesis ch. 8; Vestner, Lähner, Boyarski et al., 3DV 2017).

The correspondence maximises the quadratic assignment objective

``f(Π) = <Π, K_Y Π K_X> + μ <Π, F_Y F_Xᵀ>``  over permutations Π,

with heat kernels ``K = Φ e^{-tΛ} Φᵀ`` (spectral form, values of the heat
kernel between vertices; Φ M-orthonormal). ``f`` is convex (both kernels are
positive semi-definite), so the DC algorithm — maximise the linearisation
``G = ∇f(Π_k) = K_Y Π_k K_X + μ F_Y F_Xᵀ`` (Eq. 8.13) by one linear
assignment — never decreases it (checked and reported per iteration). The
score is formed in spectral form on the rows and columns of the current
problem only: ``G = (Ψ_r e^{-tΛ_Y}) C (Φ_c e^{-tΛ_X})ᵀ`` with the k×k matrix
``C = Ψ[map]ᵀ Φ`` summed over the current matches, in float32.

The stages, each a function of a submodule, sharing one :class:`~.state.KernelState`:

1. :func:`~.state.prepare` — spectra, surface seeds, sample orders of the finer scales.
2. :func:`~.seed_stage.initial_seed_map` — the seeds' initial assignment (descriptors, the
   functional-maps baseline, or a given map / landmarks).
3. :func:`~.seed_stage.seed_problem` — eigenfunctions, descriptor similarities and the
   anchors' alignment at the seeds (:class:`~.dc.SeedProblem`).
4. :func:`~.seed_stage.choose_start` — DC iterations of the first (largest) time from the
   initial map and from the aligned start (:func:`~.seed_stage.aligned_start`, formed on a
   thread beside the first start's iterations); the higher objective goes on
   (landmarks: the aligned start alone).
5. :func:`~.seed_stage.dc_iterations` — DC iterations at one diffusion time, each one
   :func:`~.dc.dc_step` (objective :func:`~.dc.dc_objective`, score :func:`~.dc.seed_score`);
   run over the decreasing time schedule (coarse, global alignment first).
6. :func:`~.multiscale.multiscale_refinement` — finer vertex samples solved in Voronoi
   cells (§8.3.2). When a dense map is refined (``initial``, or
   ``init="fmap"``), rows moved by less than the smallest kernel's width keep
   their input partner (:mod:`.resolution`: the kernel cannot tell such
   partners apart).
7. :func:`~.passes.kernel_result` — a map reversed on most of the shape, and limbs
   matched to their mirror-image limbs, turned by a reflection
   (:mod:`.reorientation`); final energy, optional pointwise smoothing, result.
8. :func:`~.passes.reoptimised` — where stage 7 turned anything, stages 2–7 once more
   from the turned map (a turn by a computed reflection is a start, not an
   optimum). Where it turned regions or limbs, or released limbs, the result
   stands only if it is nearer an isometry than the map without those turns
   (:func:`~.passes.declined_partial_turns`, the geodesic distortion).
9. :func:`~.passes.replaced_disagreeing_part` — a final map made of two parts whose
   geodesic distances disagree (one turned against the other) has each part
   matched again with the other as landmarks; the run nearer an isometry
   replaces it.

With ``init="best"`` (the default) stages 2–8 run from two starts side by side and a judge keeps one map
(:mod:`.starts`); before stage 9, where the kept map is right on one part and the other start's map on the
rest, their combination is optimised once more and replaces the kept map if it is nearer an isometry
(:func:`~.starts.combined_map`).

Design choices, in brief (the measurements behind them are in
``docs/decisions.md``, "Kernel matching: measured design choices"):

* Times are relative to the surface area (``t = τ · area``), so the heat
  kernel is scale-invariant; the default τ from 0.0259 to 5.18e-4 equals
  500 → 10 at the TOSCA area scale of 1.93e4.
* The kernels cannot tell left from right, so the DC iterations keep the
  orientation each region starts with. Orientation-aware descriptors
  (:mod:`corrlib.descriptors.orientation`) therefore enter the initial
  assignment; the μ term of the iterations uses the plain descriptor (their
  local noise costs accuracy there).
* A second start is formed from the kernel score of only the most similar
  initial matches (``init_fraction``), which spreads their alignment over the
  shape where the initial assignment is a coin flip (thin parts). Both starts
  run the first time's DC iterations and the higher objective goes on: a
  multi-start of the same DC problem, no start is trusted blindly.
* Landmarks stay matched: the seeds and vertices at landmarks keep their
  partners (:func:`~.seed_stage.fixed_seeds`), every assignment places the others only, and
  the one start is the landmarks' kernel score (the other seeds have no
  partner of their own). A release pass (stage 8) thereby solves the released
  limbs only.
* Seeds are farthest points of the surfaces, not of their vertices
  (:func:`~corrlib.geometry.sampling.surface_farthest_points`): independently
  remeshed shapes differ in vertex density, and a bijection of vertex seeds
  must slide matches to absorb it, which the kernel energy hardly penalises.
* Multiscale (§8.3.2): after the seeds, a vertex sample grows by ``growth``
  per scale until every vertex is included. Each pass splits the source
  sample into geodesic Voronoi cells around matched centres (farthest points,
  and more inside any cell above ``max_cell``), transfers them through the
  current map and widens the target cells by ``cell_overlap`` (a vertex near a
  border can reach its partner beyond it) and by the neighbourhoods of its rows'
  current partners (where a change of pose moves the borders apart by more than
  the overlap); every cell is an independent
  partial assignment scored with all current matches as anchors. One pass
  per scale by default: a further pass at the same scale scores the cells
  with the previous pass's matches, including those that the capacities
  (below) pushed off their best partner, and pushes again, so the map
  drifts wherever the capacities are tight; the next scale's cells have new
  borders anyway.
* A source with more vertices than the target: the finer scales sample it up
  to the target's vertex count, and the surplus vertices take the partner of
  their nearest matched vertex before the final ZoomOut step (why:
  :mod:`.resolution`).
* Area capacities (``capacity="area"``): at the finer scales a target sample
  of area ``m_y`` may take up to ``ceil(n_x · m_y / A_Y)`` source samples, a
  transportation problem that couples the area measures instead of the
  vertex counts (for differently meshed shapes). The seeds stay matched by a
  permutation: with capacities the QAP gains by piling seeds onto one target
  (``k_Y(y, y)`` is the kernel's maximum).
* ``init="best"`` (the default, :func:`~.starts.best_of_both_starts`): the whole
  pipeline from the descriptors and from the functional-maps baseline
  (sharing the spectra, samples and descriptors; side by side on two cores,
  :func:`~.starts.both_starts`), keeping the functional map's start only where
  its map is better by every measure there is: a higher kernel energy, a
  higher orientation agreement (:func:`~.passes.orientation_agreement`) and a lower
  geodesic distortion. Each alone is blind somewhere (the energy to a
  reflection of a symmetric shape, the agreement to a small flipped part,
  the distortion to the detail of a non-isometric pair). The one exception
  (:func:`~.starts.kept_start`): where the descriptor start's map reverses
  orientation on most of the shape (negative agreement) and the functional
  map's does not, the latter is kept, since only the agreement sees a mirror image.
* ``smooth_k``: a last pointwise step, one ZoomOut step (Melzi et al.
  2019): the map is projected onto the first eigenfunctions and every vertex
  takes its nearest partner in them (no longer bijective, which suits
  independently remeshed shapes). The functional map of that step is the
  mean of the estimates from the map and from its reverse
  (:func:`~corrlib.geometry.fmaps.pointwise_from_basis`), so that the coarser shape's samples do not
  carry their partners' offsets into it. The step is repeated from its own
  maps while it moves fewer partners each time (ZoomOut's alternation at one
  basis size, :func:`~corrlib.geometry.fmaps.repeated_pointwise_from_basis`), except for a map
  refined from outside the solver. By default the basis is what the smallest
  kernel resolves, the eigenfunctions with ``τ_min λ · area ≤ 1``: finer
  ones it cannot tell apart, coarser ones would blur what it resolved.
* Unequal vertex counts: rectangular assignments are padded; with
  ``partial=True`` slack variables (Eq. 8.15–8.16) let low-scoring vertices
  stay unmatched (-1 in the maps, reported).

Map convention: ``map_xy[i]`` = vertex of Y matched to vertex i of X.
"""

from __future__ import annotations

from corrlib.methods.kernel_matching.notes import copies_note, reversal_note, start_note, turn_note
from corrlib.methods.kernel_matching.params import (DEFAULT_EIGENPAIRS, DEFAULT_TAU_MIN, KernelMatchingParams,
                                                    diffusion_times)
from corrlib.methods.kernel_matching.passes import orientation_agreement
from corrlib.methods.kernel_matching.scores import kernel_energy, kernel_score
from corrlib.methods.kernel_matching.solver import solve_kernel_matching
from corrlib.methods.registry import MethodSpec, register

__all__ = ["DEFAULT_EIGENPAIRS", "DEFAULT_TAU_MIN", "KernelMatchingParams", "copies_note", "diffusion_times",
           "kernel_energy", "kernel_score", "orientation_agreement", "reversal_note", "solve_kernel_matching",
           "start_note", "turn_note"]

register(MethodSpec(
    name="kernel-matching", label="Kernel matching", inputs=("mesh", "mesh"), params=KernelMatchingParams,
    solve=solve_kernel_matching, rank=20, refines=True,
    description="Heat-kernel quadratic assignment solved as a sequence of linear assignments over decreasing "
                "diffusion times, multiscale, with slack for partial shapes (Vestner et al. 3DV 2017)."))
