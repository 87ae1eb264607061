"""Stages 7–9: one pass's result (orientation stage, final ZoomOut steps, kernel energy;
:func:`kernel_result`), the second pass from a turned map (:func:`reoptimised`), and the repair of a map of
two disagreeing parts (:func:`replaced_disagreeing_part`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from corrlib.geometry.distortion import geodesic_distortions, inconsistent_parts
from corrlib.geometry.fmaps import (ZoomOutSamples, pointwise_from_basis, repeated_pointwise_from_basis,
                                    resolved_eigenpairs)
from corrlib.geometry.spectrum import Spectrum
from corrlib.methods.base import InitialMatch, MatchResult
from corrlib.methods.kernel_matching.multiscale import multiscale_refinement
from corrlib.methods.kernel_matching.pairing import or_its_error, side_by_side
from corrlib.methods.kernel_matching.params import KernelMatchingParams, PROGRESS_SMOOTHING, diffusion_times
from corrlib.methods.kernel_matching.scores import alignment, kernel_energy
from corrlib.methods.kernel_matching.seed_stage import choose_start, dc_iterations, initial_seed_map, seed_problem
from corrlib.methods.kernel_matching.state import KernelState
from corrlib.methods.reorientation import (can_reorient, declined_extras, mean_agreement, nearer_isometry,
                                           orientation_blocks, reorient, turned_anything, with_first_pass)
from corrlib.methods.resolution import keep_input_partners, kernel_width
from corrlib.progress import Progress, Stopwatch, scaled_progress


#: DC iterations per time and refinement passes per scale of the second pass from a turned map
#: (:func:`reoptimised`): its start went through the whole schedule once already
SECOND_PASS_ITERATIONS = SECOND_PASS_PASSES = 1


def reorients(state: KernelState) -> bool:
    """Whether the orientation stage and the check of disagreeing parts apply: ``reorient`` on, no landmarks
    (they fix the orientation themselves), complete closed shapes (a cut changes a shape's reflection and
    geodesic distances; :func:`~.reorientation.can_reorient`)."""
    return state.params.reorient and state.anchors_x.size == 0 and not state.params.partial and \
        can_reorient(state.source, state.target, state.spec_y)


def final_basis_size(params: KernelMatchingParams, spec_x: Spectrum, spec_y: Spectrum, area_x: float,
                     area_y: float) -> int:
    """The eigenfunctions of the final steps: ``smooth_k`` (at most the eigenpairs computed), or for -1 those
    the smallest kernel resolves on both shapes (:func:`~corrlib.geometry.fmaps.resolved_eigenpairs`)."""
    if params.smooth_k >= 0:
        return min(params.smooth_k, spec_x.k, spec_y.k)
    tau_last = diffusion_times(params)[-1]
    return min(resolved_eigenpairs(spec_x.evals, area_x, tau_last), resolved_eigenpairs(spec_y.evals, area_y, tau_last))


def kernel_result(state: KernelState, full_map_xy: np.ndarray, full_map_yx: np.ndarray, orient: bool = True):
    """Stage 7: the turns of reversed regions, the final ZoomOut steps
    (:func:`~corrlib.geometry.fmaps.pointwise_from_basis`, repeated by
    :func:`~corrlib.geometry.fmaps.repeated_pointwise_from_basis` unless the map came from outside the solver),
    the kernel energy ``<Π, K_Y Π K_X>`` of the final map at the smallest time, the :class:`MatchResult`. A
    generator. ``orient=False`` skips the orientation stage (a map the stage has seen already)."""
    params, k, watch = state.params, state.k, state.watch
    psi, phi, trace = state.psi, state.phi, state.trace
    monotone, dc_start, n_seed = state.monotone, state.dc_start, state.n_seed
    seed_vertices_x, seed_vertices_y = state.seed_vertices_x, state.seed_vertices_y
    decay_y, decay_x = state.decays(state.taus[-1])
    turned = turned_regions = turned_parts = released = None
    released_regions = ()
    # landmarks fix the orientation themselves; a cut changes a shape's reflection and biharmonic distances
    if orient and reorients(state):
        with watch("orientation"):
            done = reorient(state.source, state.target, state.spec_x, state.spec_y, full_map_xy, full_map_yx,
                            state.orientation_blocks)
        state.before_partial_turns = done.before_partial
        full_map_xy, full_map_yx = done.map_xy, done.map_yx
        turned, turned_regions, turned_parts = done.turned, done.turned_regions, done.turned_parts
        released, released_regions = done.released, done.released_regions
    smooth_k = final_basis_size(params, state.spec_x, state.spec_y, state.source.area, state.target.area)
    if smooth_k > 0:
        yield Progress("final ZoomOut step", PROGRESS_SMOOTHING, f"nearest partners in {smooth_k} eigenfunctions")
        with watch("zoomout"):
            samples_x, samples_y = ZoomOutSamples.of_pair(state.source, state.target, state.spec_x.mass.diagonal(),
                                                          state.spec_y.mass.diagonal())
            if state.outside_map:  # a map refined from outside keeps its partners, which the reverse map lacks
                full_map_xy, full_map_yx = pointwise_from_basis(
                    full_map_xy, full_map_yx, state.spec_x, state.spec_y, smooth_k, both_directions=False,
                    samples_x=samples_x, samples_y=samples_y)
            else:
                full_map_xy, full_map_yx = repeated_pointwise_from_basis(
                    full_map_xy, full_map_yx, state.spec_x, state.spec_y, smooth_k, state.source.adjacency,
                    state.target.adjacency, state.token, samples_x, samples_y)
    # the map's own energy: landmarks are rows of the dense map already (their anchor term is the solver's)
    c = alignment(psi[full_map_xy[full_map_xy >= 0]], phi[full_map_xy >= 0])
    # at unit areas: the M-orthonormal eigenfunctions scale as 1/√area, so the energy as computed goes as
    # 1/(area_X area_Y) and a target given in millimetres would report a millionth of the same map's energy
    energy = kernel_energy(c, decay_y, decay_x) * state.source.area * state.target.area
    extras = {
        "orientation_agreement": mean_agreement(*state.orientation_blocks(), full_map_xy),
        "turned": turned is not None,
        "agreement_before_turn": None if turned is None else turned.agreement_before,
        "turned_regions": 0 if turned_regions is None else len(turned_regions.parts),
        "turned_parts": 0 if turned_parts is None else len(turned_parts.parts),
        "released_regions": len(released_regions), "released_x": released,
        "changed_trace": np.array([e["changed"] for e in trace]),
        "tau_trace": np.array([e["tau"] for e in trace]),
        "monotone": monotone, "start": dc_start, "unmatched_x": int(np.sum(full_map_xy < 0)),
        "unmatched_y": int(np.sum(full_map_yx < 0)), "n_eigs": k, "n_seeds": n_seed,
        "seeds_x": seed_vertices_x, "seeds_matched_y": seed_vertices_y,
    }
    return MatchResult("kernel-matching", full_map_xy, full_map_yx, energy, watch.times, energy_sense="max",
                       energy_meaning="QAP kernel energy <Π, K_Y Π K_X> of the shapes at unit area, at the "
                                      "smallest time (higher is better); "
                                      "energy_trace: the objective after each DC iteration (½ scaled kernel term "
                                      "+ μ descriptor term)",
                       energy_trace=np.array([e["energy"] for e in trace]), extras=extras)


def solve_prepared(state: KernelState, initial: InitialMatch | None, compete: bool = True):
    """Stages 2–7 on a prepared :class:`~.state.KernelState` (a generator; returns the :class:`MatchResult`);
    ``compete=False``: a given map does not compete with the descriptor start (a second pass, whose first
    pass had that start already)."""
    source, target = state.source, state.target
    yield from initial_seed_map(state, initial, compete)
    seed_problem(state)
    yield from choose_start(state)
    alignment = state.start_alignment
    for t_index in range(1, len(state.taus)):
        run = yield from dc_iterations(state, state.seed_map, state.prices, t_index, alignment=alignment)
        state.seed_map, alignment = run.seed_map, run.alignment
        state.trace.extend(run.entries)
    full_map_xy, full_map_yx = yield from multiscale_refinement(state)
    kept = None
    if state.refined_map is not None:  # below the smallest kernel's width the input map's partners stand
        width_x, width_y = kernel_width(state.taus[-1], source.area), kernel_width(state.taus[-1], target.area)
        kept, isometric = keep_input_partners(full_map_xy, *state.refined_map, source.vertices, target.vertices,
                                              width_x, width_y)
    result = yield from kernel_result(state, full_map_xy, full_map_yx)
    if kept is not None:
        result.extras.update(kept_matches=kept | isometric, isometric_matches=isometric)
    return result


def solved(state: KernelState, initial: InitialMatch | None = None):
    """Stages 2–7 on a prepared :class:`~.state.KernelState` and, where the orientation stage turned anything, the
    second pass (:func:`reoptimised`); a generator, returns the :class:`MatchResult`."""
    result = yield from solve_prepared(state, initial)
    if turned_anything(result.extras):
        result = yield from reoptimised(state, result)
    return result


def reoptimised(state: KernelState, turned: MatchResult):
    """The DC iterations and the finer scales run once more from a map the orientation stage turned, or with
    the rest of the map as landmarks where it found swapped limbs (a generator; returns the new
    :class:`MatchResult`).

    The first pass's decisions and map go to ``extras`` (:func:`~.reorientation.with_first_pass`).

    A turn composes the map with a *computed* reflection (:mod:`.reorientation`), which is only as exact as
    that reflection: a posed person's can be 0.02–0.07 √area off on the limbs, and the turned limbs are then
    a rough copy of the right ones, not an optimum of the kernel energy. The map is therefore a start, and
    kernel matching refines it as it refines any given map (``initial``; the partners within the smallest
    kernel's width are kept, :mod:`corrlib.methods.resolution`). The orientation stage runs again on the
    result, without a third pass. The prepared spectra, samples and descriptors are reused. From a turned map
    the pass is lighter than the first (:data:`SECOND_PASS_ITERATIONS` DC steps per time,
    :data:`SECOND_PASS_PASSES` refinement passes per scale): the map it starts from has been through the whole
    schedule already. Released limbs (below) have no start at all, so their pass is a full one.

    Swapped limbs (``extras["released_x"]``, :func:`~.reorientation.swapped_pairs`: a mirror pair of limbs, each
    sent mirror-inverted onto the other's image) are not turned by a reflection: a posed target's reflection
    is too poor on its limbs to carry them back (measured: the turned legs stay 0.27 √area off). Their
    matches are dropped, and the rest of the map becomes landmarks (anchors of every stage, kept as they are,
    :class:`~corrlib.methods.base.InitialMatch`), so the kernel energy places the limbs by their heat-kernel
    relation to the body, whose left and right the landmarks fix. A landmark run has no orientation stage,
    so there is no third pass here either.

    Turned regions and parts and released limbs are hypotheses: the region rule reads a region whose
    orientation is reversed as a left–right flip, but on a body with a second near-symmetry (an upper body
    alike in front and behind) it can be the other flip, which the left–right reflection turns into a half
    turn with the arms swapped. The result of this pass is therefore kept only where it is nearer an isometry
    than the map without those turns (:func:`declined_partial_turns`). A turn of the whole map is not judged
    so: it composes the map with a reflection, an isometry, which leaves the distortion as it was.
    """
    # the first pass reports at most PROGRESS_SMOOTHING: the second fills the rest of the bar, which never goes back
    yield Progress("re-optimising", PROGRESS_SMOOTHING, "the turned map, refined once more")
    released = turned.extras.get("released_x")
    if released is None:
        start = InitialMatch(map_xy=turned.map_xy)
    else:  # swapped limbs: re-placed by the kernel energy from the rest of the map, kept as landmarks
        kept = np.flatnonzero(~released & (turned.map_xy >= 0))
        start = InitialMatch(landmarks_x=kept, landmarks_y=turned.map_xy[kept])
    fresh = state.prepared()
    if released is None:  # a turned map: every vertex starts from a map that went through the whole schedule
        fresh.params = replace(state.params, iters_per_time=min(state.params.iters_per_time, SECOND_PASS_ITERATIONS),
                               passes=min(state.params.passes, SECOND_PASS_PASSES))
    result = yield from scaled_progress(solve_prepared(fresh, start, compete=False),
                                        PROGRESS_SMOOTHING, 1.0, "second pass")
    with_first_pass(result.extras, turned.extras, turned.map_xy, turned.energy)
    if state.before_partial_turns is not None:
        kept = yield from declined_partial_turns(state, turned, result)
        if kept is not None:
            return kept
    return result


def declined_partial_turns(state: KernelState, first: MatchResult, second: MatchResult):
    """The first pass's map without its partial turns, where the second pass made the map farther from an
    isometry; else None (a generator).

    Compares the geodesic distortion of the map before the orientation stage turned regions or parts or
    released limbs (``state.before_partial_turns``; after a whole-map turn, if any) with that of the second
    pass's result (:func:`~corrlib.methods.reorientation.nearer_isometry`: a right turn removes a
    mirror-inverted stretch of the map and lowers it; a turn by the wrong symmetry swaps limbs and raises it;
    the kernel energy is higher after either). The distortions go to ``extras`` of the map returned; a
    declined result is the first pass's map through the final ZoomOut steps, with its energy and trace, and
    ``declined_turns`` (:func:`~corrlib.methods.reorientation.declined_extras`).
    """
    before_xy, before_yx = state.before_partial_turns
    with state.watch("orientation"):
        keep_after, measured = nearer_isometry(state.source, state.target, before_xy, second.map_xy,
                                               state.pair_distances())
    second.extras.update(measured)
    if keep_after:
        return None
    kept = yield from scaled_progress(kernel_result(state, before_xy, before_yx, orient=False), 1.0, 1.0,
                                      "the turns undone")
    kept.extras.update(declined_extras(first.extras, measured))
    return kept


def replaced_disagreeing_part(state: KernelState, found: MatchResult):
    """Stage 9: a map made of two parts that disagree, each part placed again from the other; a generator,
    returns the :class:`MatchResult` kept.

    The DC iterations keep what the first times decided, and a body alike in front and behind (an upper body
    of limbs and a torso without a face) can leave the first times with one part turned half round against
    the rest: arms swapped, chest onto back, hips and legs right. Each part is then nearly an isometry of its
    own, and the kernel energy at the smallest time hardly sees the seam, but the geodesic distances between
    the parts are off by the body's width. :func:`~corrlib.geometry.distortion.inconsistent_parts` finds the
    two parts; where they disagree (:attr:`~corrlib.geometry.distortion.MapParts.disagree`), each part in
    turn is kept as landmarks and the other matched again from it (two landmark runs, side by side,
    :func:`~.pairing.side_by_side`), as a release pass places swapped limbs. The run of least geodesic distortion
    replaces the map where it is nearer an isometry than the map found; which part was wrong is not
    guessed. ``extras``: ``disagreement_ratio`` always, and where the runs were made
    ``disagreement_distortions`` (the map found, then the run keeping the first part, then the second; ``inf``
    for a run that failed) and
    ``replaced_part`` (the count of source vertices matched again, 0 where the map found was kept).
    """
    if not reorients(state):
        return found
    with state.watch("disagreeing parts"):
        parts = inconsistent_parts(state.source, state.target, found.map_xy, state.pair_distances())
    if parts is None:
        return found
    found.extras["disagreement_ratio"] = parts.ratio
    if not parts.disagree:
        return found
    yield Progress("disagreeing parts", 1.0, f"two parts of the map disagree ({parts.ratio:.1f}× the distortion "
                                             "within them); each is matched again from the other")
    states, landmarks = [], []
    for kept in (parts.part, ~parts.part):
        states.append(state.prepared())
        states[-1].watch = Stopwatch()
        landmarks.append(np.flatnonzero(kept & (found.map_xy >= 0)))

    def placing(index):  # the run keeping part `index`; a failed run returns its error instead of a map
        start = InitialMatch(landmarks_x=landmarks[index], landmarks_y=found.map_xy[landmarks[index]])
        return lambda fresh: or_its_error(solve_prepared(fresh, start, compete=False))

    with state.watch("disagreeing parts"):  # the bar stays full: the match was complete before this stage
        placed = yield from scaled_progress(side_by_side(states[0], states[1], placing(0), placing(1), (
            "keeping the first part", "keeping the second part")), 1.0, 1.0)
        maps = [found.map_xy] + [outcome.map_xy for outcome in placed if isinstance(outcome, MatchResult)]
        measured = iter(geodesic_distortions(state.source, state.target, maps, state.pair_distances()))
    distortions = [next(measured)] + [next(measured) if isinstance(outcome, MatchResult) else float("inf")
                                      for outcome in placed]
    found.extras.update(disagreement_distortions=distortions, replaced_part=0)
    best = int(np.argmin(distortions))  # the map found on a tie
    if best == 0:
        return found
    result = placed[best - 1]
    replaced = int(found.map_xy.size - landmarks[best - 1].size)  # the source vertices matched again
    result.extras = {**found.extras, **result.extras, "replaced_part": replaced}
    result.timings = found.timings  # with this stage's time (the landmark runs' own timings are its parts)
    return result


def orientation_agreement(source, target, map_xy: np.ndarray, spec_x: Spectrum, spec_y: Spectrum) -> float:
    """Mean agreement ``<O_X(x), O_Y(m(x))>`` of the standardised orientation-aware descriptors along a map.

    The descriptors (:func:`~corrlib.descriptors.orientation.orientation_descriptors`, signed area forms of
    heat kernel signature pairs) change sign under a reflection, so the agreement is large for a map that
    keeps left on left and negative for its mirror image — which the kernel energy cannot tell apart, since
    a reflection of a symmetric shape preserves the heat kernels. Unmatched vertices (-1) are left out.
    """
    return mean_agreement(*orientation_blocks(source, target, spec_x, spec_y), map_xy)
