"""The registered solver (:func:`solve_kernel_matching`): one start or both, and meshes finer than
``mesh_vertices`` matched on remeshed copies and the map carried back (:func:`matched_on_copies`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from corrlib.geometry.lifting import MatchedCopy, lifted_maps, matched_copy
from corrlib.geometry.spectrum import mesh_spectra
from corrlib.methods.base import InitialMatch
from corrlib.methods.kernel_matching.params import KernelMatchingParams, SUGGESTED_MESH_VERTICES
from corrlib.methods.kernel_matching.passes import final_basis_size, replaced_disagreeing_part, solved
from corrlib.methods.kernel_matching.starts import best_of_both_starts
from corrlib.methods.kernel_matching.state import prepare
from corrlib.progress import Progress, Stopwatch, scaled_progress


#: meshes above this many vertices get the suggestion of ``mesh_vertices`` in the progress messages: at full
#: resolution their pairs take minutes and gigabytes (see docs/decisions.md)
LARGE_MESH_VERTICES = 40_000
#: the share of the progress bar of the match on the copies (the rest: carrying the map to the fine meshes)
PROGRESS_COPIES = 0.9


def kernel_matching(source, target, params: KernelMatchingParams, token, initial: InitialMatch | None = None):
    """Solver generator (thesis ch. 8, see the package docstring); returns a :class:`MatchResult`.

    Prepare the spectra and seeds, assign the seeds initially, run the DC iterations of the first time from
    one or two starts and keep the better, continue over the decreasing times, refine on finer scales; a
    refined dense map keeps its partners within the smallest kernel's width, and farther moved ones where they are
    the more isometric partner (:mod:`corrlib.methods.resolution`; ``extras["kept_matches"]``, the latter also
    in ``extras["isometric_matches"]``). Where the orientation stage turned anything, the turned map is
    optimised once more (:func:`~.passes.reoptimised`).
    """
    state = yield from prepare(source, target, params, token)
    result = yield from solved(state, initial)
    result = yield from replaced_disagreeing_part(state, result)
    yield Progress("done", 1.0, f"energy {result.energy:.6g}")
    return result


def solve_kernel_matching(source, target, params: KernelMatchingParams, token, *,
                          initial: InitialMatch | None = None):
    """Registered solver (``initial``: optional :class:`InitialMatch` for refinement)."""
    if initial is None:
        if 0 < 2 * params.mesh_vertices < max(source.n_vertices, target.n_vertices):
            yield Progress("remeshing", 0.0, f"copies of {params.mesh_vertices} vertices (mesh_vertices)")
        copy_x, copy_y = matched_copy(source, params.mesh_vertices), matched_copy(target, params.mesh_vertices)
        if copy_x.remeshed or copy_y.remeshed:
            return (yield from matched_on_copies(source, target, copy_x, copy_y, params, token))
        if max(source.n_vertices, target.n_vertices) > LARGE_MESH_VERTICES:
            yield Progress("eigenpairs", 0.0, f"{max(source.n_vertices, target.n_vertices)} vertices at full "
                                              f"resolution take minutes; mesh_vertices={SUGGESTED_MESH_VERTICES} "
                                              "matches on remeshed copies in seconds")
    if initial is None and params.init == "best":
        return (yield from best_of_both_starts(source, target, params, token))
    return (yield from kernel_matching(source, target, params, token, initial))


def matched_on_copies(source, target, copy_x: MatchedCopy, copy_y: MatchedCopy, params: KernelMatchingParams,
                      token):
    """Kernel matching of meshes finer than ``mesh_vertices``: the copies matched, the maps carried to the
    originals (:mod:`corrlib.geometry.lifting`) with the final steps' basis (``smooth_k``).

    Diagnostics that name vertices of the copies (arrays in ``extras``) are dropped; ``extras["matched_on"]``
    gives the copies' vertex counts.
    """
    inner = replace(params, mesh_vertices=0)
    label = f"matched on copies of {copy_x.mesh.n_vertices} and {copy_y.mesh.n_vertices} vertices"
    solver = (best_of_both_starts(copy_x.mesh, copy_y.mesh, inner, token) if params.init == "best" else
              kernel_matching(copy_x.mesh, copy_y.mesh, inner, token, None))
    result = yield from scaled_progress(solver, 0.0, PROGRESS_COPIES, label)
    spec_x, spec_y = mesh_spectra((copy_x.mesh, copy_y.mesh), params.n_eigs)  # the copies' (cached)
    k = final_basis_size(params, spec_x, spec_y, copy_x.mesh.area, copy_y.mesh.area)
    yield Progress("final ZoomOut step", PROGRESS_COPIES,
                   f"the map carried to {source.n_vertices} and {target.n_vertices} vertices, {k} eigenfunctions")
    watch = Stopwatch()
    with watch("lift"):
        result.map_xy, result.map_yx = lifted_maps(result.map_xy, result.map_yx, source, target, copy_x, copy_y,
                                                   spec_x, spec_y, k, token)
    result.timings.update(watch.times)
    result.extras = {key: value for key, value in result.extras.items() if not isinstance(value, np.ndarray)}
    result.extras["matched_on"] = (copy_x.mesh.n_vertices, copy_y.mesh.n_vertices)
    return result
