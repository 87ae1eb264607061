"""``init="best"``: kernel matching from the descriptor start and from the functional-maps baseline's map,
both to the end, the judge between their maps (:func:`best_of_both_starts`), and the kept map with a part
taken from the other start's where that is nearer an isometry (:func:`combined_map`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from corrlib.errors import CorrError
from corrlib.geometry.distortion import RESOLVED_EDGES, PairDistances, geodesic_distortions, inconsistent_parts
from corrlib.methods.base import InitialMatch, MatchResult
from corrlib.methods.kernel_matching.pairing import side_by_side
from corrlib.methods.kernel_matching.params import KernelMatchingParams
from corrlib.methods.kernel_matching.passes import (SECOND_PASS_ITERATIONS, SECOND_PASS_PASSES,
                                                    replaced_disagreeing_part, reorients, solve_prepared, solved)
from corrlib.methods.kernel_matching.state import KernelState, prepare
from corrlib.progress import Progress, Stopwatch, scaled_progress

#: a combined map (:func:`combined_map`) is tried only where its per-sample distortions are below each whole
#: map's with a paired t statistic under this: lower beyond the spread of the samples (about the two-sided 5 %
#: level over the 100 samples)
SIGNIFICANT_T = -2.0


def start_measures(source, target, results: dict, distances: PairDistances | None = None) -> dict:
    """The three measures by which :func:`best_of_both_starts` compares its maps, per start.

    Returns ``{init: {"energy", "agreement", "distortion"}}``: the final kernel energy (higher is better;
    both runs share the spectra and times, so the energies compare), the :func:`~.passes.orientation_agreement`
    (higher) and the geodesic distortion per √area
    (:func:`~corrlib.geometry.distortion.geodesic_distortions`, lower; ``distances``: the pair's, shared).
    """
    inits = list(results)
    distortions = geodesic_distortions(source, target, [results[init].map_xy for init in inits], distances)
    return {init: {"energy": float(results[init].energy),
                   "agreement": float(results[init].extras["orientation_agreement"]),
                   "distortion": float(d)} for init, d in zip(inits, distortions)}


def dominates(a: dict, b: dict) -> bool:
    """Whether the measures ``a`` are better than ``b`` in all three (:func:`start_measures`)."""
    return a["energy"] > b["energy"] and a["agreement"] > b["agreement"] and a["distortion"] < b["distortion"]


def reverses_where_other_keeps(a: dict, b: dict) -> bool:
    """Whether the map measured by ``a`` reverses orientation on most of the shape (negative agreement, what
    :func:`~.notes.reversal_note` warns of) and the one measured by ``b`` does not (:func:`start_measures`)."""
    return a["agreement"] < 0 <= b["agreement"]


def kept_start(measures: dict) -> str:
    """The start whose map :func:`best_of_both_starts` keeps, by their :func:`start_measures`: the functional
    map's where the descriptor start's map reverses orientation on most of the shape and its own does not
    (agreements of opposite signs: the kernel energy and the distortion cannot see a mirror image, and the
    method warns of a negative agreement, :func:`~.notes.reversal_note`), or where it :func:`dominates`; else
    the descriptor start's."""
    fmap, descriptors = measures["fmap"], measures["descriptors"]
    if reverses_where_other_keeps(descriptors, fmap) or dominates(fmap, descriptors):
        return "fmap"
    return "descriptors"


def paired_t(values: np.ndarray, reference: np.ndarray) -> float:
    """The paired t statistic of ``values − reference`` ((k,) float each): the mean difference over its
    standard error; ±inf where every difference is the same non-zero number, 0 where all are zero."""
    difference = np.asarray(values, dtype=float) - np.asarray(reference, dtype=float)
    spread = float(difference.std(ddof=1)) if difference.size > 1 else 0.0
    mean = float(difference.mean()) if difference.size else 0.0
    if spread > 0:
        return mean / (spread / np.sqrt(difference.size))
    return float(np.sign(mean) * np.inf) if mean else 0.0


@dataclass(frozen=True)
class CombinedMap:
    """The kept start's map with one part taken from the other start's map (:func:`combined_map`).

    Attributes
    ----------
    map_xy : (n_X,) int
    taken : (n_X,) bool
        The source vertices whose partner is the other start's.
    distortions : tuple of float
        Geodesic distortion per √area of the kept map, the other start's map and the combination.
    """

    map_xy: np.ndarray
    taken: np.ndarray
    distortions: tuple


def combined_map(kept_xy: np.ndarray, other_xy: np.ndarray, distances: PairDistances) -> CombinedMap | None:
    """The kept start's map with one of its two most inconsistent parts taken from the other start's map,
    where that combination is nearer an isometry than both whole maps; None elsewhere.

    A map can be right on one part of a body and turned on the rest (the legs right, an upper body alike in
    front and behind turned half round), while the other start's map is right where this one is turned.
    The split is :func:`~corrlib.geometry.distortion.inconsistent_parts` of the kept map. Each part is
    taken from the other start only where the two starts' partners there lie more than
    :data:`~corrlib.geometry.distortion.RESOLVED_EDGES` mean edge lengths apart (they disagree by more
    than the edge paths resolve; two right maps never do), and the combination is kept where its
    per-sample geodesic distortions are lower than each whole map's by a :func:`paired_t` below
    :data:`SIGNIFICANT_T` (the distortion is the definition of an isometry; the test keeps two near-equal
    maps from being told apart by the samples' noise). Of two such parts the less distorted combination.

    Parameters
    ----------
    kept_xy, other_xy : (n_X,) int
        The kept start's map and the other start's; -1 where unmatched.
    distances : PairDistances
        The pair's distances, shared with the other judges of the match.
    """
    source, target = distances.source, distances.target
    parts = inconsistent_parts(source, target, kept_xy, distances)
    if parts is None:
        return None
    sample = distances.sample
    measured = [distances.sample_distortions(m) for m in (kept_xy, other_xy)]
    kept_images, other_images = kept_xy[sample], other_xy[sample]
    matched = (kept_images >= 0) & (other_images >= 0)
    apart = np.zeros(sample.size)  # each sample's two partners, how far apart on the target
    apart[matched] = distances.from_images(kept_images[matched])[np.arange(matched.sum()), other_images[matched]]
    best = None
    for side in (parts.part, ~parts.part):
        in_side = matched & side[sample]
        if not in_side.any() or not apart[in_side].mean() > RESOLVED_EDGES * parts.resolution:
            continue
        mixed = np.where(side, other_xy, kept_xy)
        samples, values = distances.sample_distortions(mixed)
        if any(not np.array_equal(samples, whole[0]) for whole in measured):  # other samples matched: no pairs
            continue
        if all(paired_t(values, whole[1]) < SIGNIFICANT_T for whole in measured):
            distortion = float(values.mean())
            if best is None or distortion < best.distortions[2]:
                best = CombinedMap(mixed, side.copy(), (float(measured[0][1].mean()), float(measured[1][1].mean()),
                                                        distortion))
    return best


def from_combined_map(state: KernelState, kept: MatchResult, combined: CombinedMap):
    """Kernel matching once more from a :class:`CombinedMap` (a generator; returns the :class:`MatchResult`
    kept): a pass as after a turn (the map went through the whole schedule, part by part, in the two starts;
    :func:`~.passes.reoptimised`), whose result replaces the kept map where it is nearer an isometry.
    ``extras["combined_starts"]``: the count of source vertices taken from the other start and the geodesic
    distortions of the kept map, the other start's, the combination and its optimised map."""
    yield Progress("combining the starts", 1.0, f"{int(combined.taken.sum())} source vertices take the other "
                                                "start's partners (nearer an isometry); optimised once more")
    fresh = state.prepared()
    fresh.watch = Stopwatch()
    fresh.params = replace(state.params, iters_per_time=min(state.params.iters_per_time, SECOND_PASS_ITERATIONS),
                           passes=min(state.params.passes, SECOND_PASS_PASSES))
    with state.watch("combined starts"):
        optimised = yield from scaled_progress(solve_prepared(fresh, InitialMatch(map_xy=combined.map_xy),
                                                              compete=False), 1.0, 1.0)
        distortion = geodesic_distortions(state.source, state.target, [optimised.map_xy], state.pair_distances())[0]
    record = {"taken": int(combined.taken.sum()), "distortions": [*combined.distortions, distortion]}
    if not distortion < combined.distortions[0]:  # the kept map is as near an isometry: it stays
        kept.extras["combined_starts"] = {**record, "kept": False}
        return kept
    optimised.extras = {**kept.extras, **optimised.extras, "combined_starts": {**record, "kept": True}}
    optimised.timings = kept.timings  # with this stage's time, added by the caller's watch
    return optimised


def both_starts(first: KernelState, second: KernelState):
    """Kernel matching from two prepared states (:func:`~.pairing.side_by_side`, each :func:`~.passes.solved`).
    A generator; returns ``{init: MatchResult}``, where the second start's value is its
    :class:`~corrlib.errors.CorrError` if it failed (the first start's errors, and a cancellation, are
    raised)."""
    inits = (first.params.init, second.params.init)
    results = yield from side_by_side(first, second, solved, solved,
                                      (f"start 1/2 ({inits[0]})", f"start 2/2 ({inits[1]})"))
    return dict(zip(inits, results))


def best_of_both_starts(source, target, params: KernelMatchingParams, token):
    """``init="best"``: kernel matching from the descriptor start and from the functional-maps baseline's
    map; the latter is kept only where its map is better by all three measures of :func:`start_measures`
    (higher kernel energy, higher orientation agreement, lower geodesic distortion), or where it keeps the
    orientation that the descriptor start's map reverses (:func:`kept_start`), else the descriptor start's.
    Where the kept map is right on one part and the other start's on the rest, a combination of the two,
    nearer an isometry than either, is optimised once more and replaces it (:func:`combined_map`,
    :func:`from_combined_map`; with the orientation stage, ``reorient``).

    Why both: the descriptor start (SHOT and the orientation-aware descriptors, point by point) can commit
    part of a non-isometric pair, or of a noisy one, to the wrong limb, where the functional map (a
    spectral fit of the whole shape, :mod:`~corrlib.methods.baselines`) holds; on a symmetric body the
    functional map can be a half turn or a partial flip that the descriptor start avoids. Why all three:
    each measure alone is blind somewhere — the kernel energy to maps that differ by a symmetry, the
    orientation agreement to a flip of a small part, the distortion to the detail of a non-isometric
    pair — so the default start gives way only to a map that no measure finds worse (see
    ``docs/decisions.md``). ``extras["init"]`` names the start kept and ``extras["start_measures"]`` holds
    both starts' measures; the timings are those of the map kept plus ``"other start"`` (the other run's
    sum). Where the functional map's start fails (a :class:`~corrlib.errors.CorrError`, e.g. descriptors that
    are the same at every vertex of a very regular shape), the descriptor start's map is returned with
    ``extras["other_start_error"]`` (the message; :func:`~.notes.start_note` tells the user).
    """
    state = yield from prepare(source, target, params, token)
    yield Progress("descriptors", 0.0, f"{params.descriptor}, shared by both starts")  # each start reports from 0
    state.descriptors()
    if params.mu > 0:
        state.seed_descriptor_similarity()
    with state.watch("orientation"):
        state.orientation_blocks()
    starts = {}
    for init in ("descriptors", "fmap"):
        starts[init] = state.prepared()  # the spectra, samples and descriptors
        starts[init].params, starts[init].watch = replace(params, init=init), Stopwatch()  # each times itself
    results = yield from both_starts(starts["descriptors"], starts["fmap"])
    if isinstance(results["fmap"], CorrError):  # e.g. descriptors that cannot tell a shape's points apart
        kept, result = "descriptors", results["descriptors"]
        result.extras.update({"init": kept, "start_measures": None, "other_start_error": str(results["fmap"])})
    else:
        with state.watch("orientation"):
            measures = start_measures(source, target, results, state.pair_distances())
        kept = kept_start(measures)
        other = "fmap" if kept == "descriptors" else "descriptors"
        result = results[kept]
        result.extras.update({"init": kept, "start_measures": measures})
        result.timings["other start"] = float(sum(results[other].timings.values()))
        if reorients(state):
            with state.watch("combined starts"):
                combined = combined_map(result.map_xy, results[other].map_xy, state.pair_distances())
            if combined is not None:
                result = yield from from_combined_map(state, result, combined)
    result = yield from replaced_disagreeing_part(state, result)
    for stage, seconds in state.watch.times.items():  # the shared stages: spectra, samples, the judge
        result.timings[stage] = result.timings.get(stage, 0.0) + seconds
    yield Progress("done", 1.0, f"{kept} start kept, energy {result.energy:.6g}")
    return result
