"""``init="best"``: kernel matching from the descriptor start and from the functional-maps baseline's map,
both to the end, and the judge between their maps (:func:`best_of_both_starts`).
"""

from __future__ import annotations

from dataclasses import replace

from corrlib.errors import CorrError
from corrlib.geometry.distortion import PairDistances, geodesic_distortions
from corrlib.methods.kernel_matching.pairing import side_by_side
from corrlib.methods.kernel_matching.params import KernelMatchingParams
from corrlib.methods.kernel_matching.passes import replaced_disagreeing_part, solved
from corrlib.methods.kernel_matching.state import KernelState, prepare
from corrlib.progress import Progress, Stopwatch


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
    result = yield from replaced_disagreeing_part(state, result)
    for stage, seconds in state.watch.times.items():  # the shared stages: spectra, samples, the judge
        result.timings[stage] = result.timings.get(stage, 0.0) + seconds
    yield Progress("done", 1.0, f"{kept} start kept, energy {result.energy:.6g}")
    return result
