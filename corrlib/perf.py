"""Performance benchmarks (``corr perf SUITE``): print figures, assert nothing.

Each suite measures the targets named in its issue on the bundled shapes and
prints one line per figure: best wall-clock time over ``repeat`` runs and,
where relevant, peak resident memory growth.
"""

from __future__ import annotations

import os
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from corrlib.errors import ParameterError
from corrlib.progress import peak_rss_mb


def _best_time(fn: Callable[[], object], repeat: int) -> tuple[float, object]:
    best, out = np.inf, None
    for _ in range(max(repeat, 1)):
        start = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - start)
    return best, out


def _line(name: str, seconds: float, extra: str = "") -> None:
    print(f"{name:<58} {seconds:8.3f} s  {extra}", flush=True)


def _cli_match_wall(method: str, source: Path, target: Path, cache_dir: Path, out_dir: Path) -> float:
    """Wall-clock seconds of ``corr match SOURCE TARGET --method METHOD`` in a fresh interpreter (what a user
    waits for: start-up, imports, compiled-kernel loading, the match, the files and pictures), with the
    spectra cache at ``cache_dir``."""
    import subprocess
    import sys

    env = dict(os.environ, CORRLIB_CACHE_DIR=str(cache_dir))
    command = [sys.executable, "-c", "import sys; from corrlib.cli import main; sys.exit(main(sys.argv[1:]))",
               "match", str(source), str(target), "--method", method, "-o", str(out_dir / "result"), "-q"]
    start = time.perf_counter()
    done = subprocess.run(command, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"corr match failed ({done.returncode}): {done.stderr.strip()[-500:]}")
    return wall


def _cli_walls(method: str, pairs: list[tuple[Path, Path]], warm_too: bool) -> None:
    """Print the CLI wall time of every pair with an empty spectra cache and (``warm_too``) with a filled one."""
    for source, target in pairs:
        with tempfile.TemporaryDirectory() as tmp:
            cache, out = Path(tmp) / "cache", Path(tmp) / "out"
            out.mkdir()
            cold = _cli_match_wall(method, source, target, cache, out)
            extra = ""
            if warm_too:
                extra = f"warm spectra cache {_cli_match_wall(method, source, target, cache, out):.2f} s"
            _line(f"corr match {source.stem} {target.stem} --method {method}, CLI wall, cold cache  "
                  f"[issue 19: {'<= 10 s' if method == 'kernel-matching' else '<= 60 s'}]", cold, extra)


def suite_foundation(repeat: int, quick: bool = False) -> None:
    """Issue 2 targets: eigenpairs, SHOT, geodesic error, spectrum cache (``quick``: fewer cases)."""
    from corrlib.descriptors.shot import shot
    from corrlib.evaluation import geodesic_errors
    from corrlib.geometry.laplacian import mesh_laplacian
    from corrlib.geometry.spectrum import eigenpairs, mesh_spectrum
    from corrlib.io import load_mesh, load_vts
    from corrlib.methods import solve
    from corrlib.resources import resource

    cat0 = load_mesh(resource("data/tosca/cat0.off"))
    cat1 = load_mesh(resource("data/tosca/cat1.off"))
    print(f"machine: {os.cpu_count()} cores; shape: cat0, {cat0.n_vertices} vertices")
    t_lap, (stiff, mass) = _best_time(lambda: mesh_laplacian(cat0), repeat)
    _line("cotan Laplacian + lumped mass", t_lap)
    for k in ((200,) if quick else (200, 500)):
        reference = None
        for method in ("eigsh", "slicing", "auto"):
            t, (evals, evecs) = _best_time(lambda m=method: eigenpairs(stiff, mass, k, method=m), repeat)
            if reference is None:
                reference = evals
                diff = 0.0
            else:
                diff = float(np.max(np.abs(evals - reference)) / reference[-1])
            gram = evecs.T @ (mass @ evecs)
            _line(f"{k} eigenpairs, method={method}", t,
                  f"max rel. eigenvalue diff vs eigsh {diff:.1e}, M-orthonormality defect "
                  f"{np.max(np.abs(gram - np.eye(k))):.1e}")
    t200 = _best_time(lambda: (mesh_laplacian(cat0), eigenpairs(stiff, mass, 200)), repeat)[0]
    _line("Laplacian + 200 eigenpairs (auto)  [target <= 3 s]", t200)
    with tempfile.TemporaryDirectory() as tmp:
        old = os.environ.get("CORRLIB_CACHE_DIR")
        os.environ["CORRLIB_CACHE_DIR"] = tmp
        try:
            t_cold = _best_time(lambda: mesh_spectrum(cat0, 200), 1)[0]
            t_warm = _best_time(lambda: mesh_spectrum(cat0, 200), repeat)[0]
        finally:
            if old is None:
                os.environ.pop("CORRLIB_CACHE_DIR")
            else:
                os.environ["CORRLIB_CACHE_DIR"] = old
    _line("mesh_spectrum k=200, empty disk cache", t_cold)
    _line("mesh_spectrum k=200, from the disk cache", t_warm)

    start = time.perf_counter()
    shot(cat0.vertices, cat0.faces, normals=cat0.vertex_normals)
    _line("SHOT 5k vertices, first call (incl. numba compile or cache load)  [<= 5 s]",
          time.perf_counter() - start)
    t_shot = _best_time(lambda: shot(cat0.vertices, cat0.faces, normals=cat0.vertex_normals), repeat)[0]
    _line("SHOT 5k vertices, warm  [target <= 5 s]", t_shot)

    gt0 = load_vts(resource("data/tosca/cat0.vts"))
    gt1 = load_vts(resource("data/tosca/cat1.vts"))
    result = solve("descriptor-nn", cat0, cat1)
    t_eval, report = _best_time(lambda: geodesic_errors(result.map_xy, cat1, gt0, gt1), repeat)
    _line(f"geodesic error, {gt0.size}-point map (descriptor NN, exact)  [<= 5 s]", t_eval,
          f"mean error {report.summary()['mean']:.3f}")
    if quick:
        return
    random_map = np.random.default_rng(0).integers(0, cat1.n_vertices, cat0.n_vertices)
    t_rand, rep_rand = _best_time(lambda: geodesic_errors(random_map, cat1, gt0, gt1), 1)
    _line(f"geodesic error, {gt0.size}-point random map (worst case, exact)", t_rand,
          f"mean error {rep_rand.summary()['mean']:.3f}")
    t_heat = _best_time(lambda: geodesic_errors(result.map_xy, cat1, gt0, gt1, method="heat"), 1)[0]
    _line(f"geodesic error, {gt0.size}-point map (heat method)", t_heat)
    print(f"peak resident memory: {peak_rss_mb():.0f} MB")


def suite_contour3d(repeat: int, quick: bool = False) -> None:
    """Issue 3 targets: global optimum 200 x 5k, time per layered Dijkstra, retrieval over 20 meshes."""
    from corrlib.geometry.cyclic_paths import ProductGraph
    from corrlib.geometry.sections import render_silhouette
    from corrlib.io import load_contour, load_mesh, save_mesh
    from corrlib.methods.contour3d import Contour3DParams, node_costs, prepare_mesh, prepare_query
    from corrlib.methods import solve
    from corrlib.progress import run
    from corrlib.resources import resource
    from corrlib.retrieval import retrieval_params, retrieve

    wolf0 = load_mesh(resource("data/tosca/wolf0.off"))
    cat1 = load_mesh(resource("data/tosca/cat1.off"))
    axes = np.linalg.svd(wolf0.vertices - wolf0.vertices.mean(axis=0), full_matrices=False)[2]
    query = render_silhouette(wolf0, axes[2], 400, up=axes[1])
    print(f"machine: {os.cpu_count()} cores; query: silhouette of wolf0 ({query.n_points} outline pixels)")
    params = Contour3DParams(n_contour=200)
    prepared = prepare_query(query, params)
    target = prepare_mesh(cat1, params)
    model, default_features = next(iter(target.features.items()))  # the default shape model's (first)
    graph = ProductGraph(node_costs(prepared.model_features(model), default_features), prepared.points, target.vertices,
                         cat1.adjacency)
    everything = np.ones(cat1.n_vertices, dtype=bool)
    t_run = _best_time(lambda: graph.shortest(everything, everything), repeat)[0]
    _line(f"one layered Dijkstra, 200 x {cat1.n_vertices}, all starts, unpruned", t_run)
    paper_cost = {"features": "paper", "axis_weight": 0.0, "model": "flat", "view": "front", "metric": "euclidean"}
    cases = [("default cost", 0.05, {})] if quick else [
        ("default cost", 0.0, {}), ("default cost", 0.05, {}), ("whole-surface model", 0.0, {"model": "whole"}),
        ("half-shape model", 0.0, {"model": "half"}), ("half-shape model, one axis", 0.0,
                                                        {"model": "half", "axis_modes": 1}),
        ("CVPR 2016 energy", 0.0, paper_cost), ("Euclidean product metric", 0.0, {"metric": "euclidean"}),
        ("default cost, elastic energy", 0.0, {"energy": "elastic"})]
    for label, eps, extra in cases:
        t, result = _best_time(lambda e=eps, kw=extra: solve("contour3d", query, cat1, n_contour=200, eps=e, **kw),
                               1 if "elastic" in label else repeat)
        search = result.search
        _line(f"match 200-point contour to cat1 ({cat1.n_vertices} v), {label}, eps={eps}"
              + ("  [target <= 2 s]" if eps == 0 else ""), t,
              f"energy {result.energy:.5g}, lower bound {search.lower_bound:.5g}, {search.iterations} B&B "
              f"iterations, {search.dijkstra_runs} Dijkstra runs of {search.seconds_per_dijkstra:.3f} s")
    drawing = load_contour(resource("data/silhouettes/drawn/wolf.txt"))
    t, result = _best_time(lambda: solve("contour-views", drawing, wolf0), repeat)
    _line(f"contour-views: the drawn wolf to wolf0 ({wolf0.n_vertices} v), {result.extras['views']} views", t,
          ", ".join(f"{stage} {seconds:.2f} s" for stage, seconds in result.timings.items() if stage != "total"))
    if quick:
        return
    with tempfile.TemporaryDirectory() as tmp:
        rng = np.random.default_rng(0)
        sources = ["data/tosca/cat0.off", "data/tosca/cat1.off", "data/sumner/lion-00.off",
                   "data/tosca/wolf0.off", "data/tosca/wolf1.off"]
        files = []
        for i in range(20):
            mesh = load_mesh(resource(sources[i % len(sources)]))
            q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
            perm = rng.permutation(mesh.n_vertices)
            inv = np.argsort(perm)
            path = os.path.join(tmp, f"{mesh.name[:-4].rstrip('-0123456789')}{i:02d}.off")
            save_mesh(path, mesh.vertices[perm] @ q.T, inv[mesh.faces])
            files.append(path)
        sizes = [load_mesh(f).n_vertices for f in files]
        print(f"collection: 20 meshes of {min(sizes)}-{max(sizes)} vertices (rotated, vertex order shuffled)")
        rparams = retrieval_params(eps=0.05)
        for jobs in (2, 1):
            os.environ["CORRLIB_CACHE_DIR"] = os.path.join(tmp, f"cache{jobs}")  # cold spectra cache
            start = time.perf_counter()
            hits = run(retrieve(query, files, rparams, jobs=jobs))
            elapsed = time.perf_counter() - start
            _line(f"retrieve 1 query against 20 meshes, jobs={jobs}, cold cache" +
                  ("  [target <= 60 s]" if jobs == 2 else ""), elapsed,
                  f"top 4: {', '.join(os.path.basename(str(h.path)) for h in hits[:4])}")
        os.environ.pop("CORRLIB_CACHE_DIR")


def suite_kernel(repeat: int, quick: bool = False) -> None:
    """Issue 4 targets: the whole kernel-matching pipeline on a 5k pair; auction vs exact assignment."""
    from corrlib.assignment import assignment_score, linear_assignment
    from corrlib.evaluation import geodesic_errors
    from corrlib.geometry.sampling import farthest_point_sampling
    from corrlib.geometry.spectrum import mesh_spectrum
    from corrlib.io import load_mesh, load_vts
    from corrlib.methods import solve
    from corrlib.methods.kernel_matching import kernel_score
    from corrlib.resources import resource

    cat0 = load_mesh(resource("data/tosca/cat0.off"))
    cat1 = load_mesh(resource("data/tosca/cat1.off"))
    print(f"machine: {os.cpu_count()} cores; pair: cat0 ({cat0.n_vertices} v) -> cat1 ({cat1.n_vertices} v)")
    with tempfile.TemporaryDirectory() as tmp:
        old = os.environ.get("CORRLIB_CACHE_DIR")
        os.environ["CORRLIB_CACHE_DIR"] = tmp  # cold: eigenpairs are part of the pipeline
        try:
            rss_before = peak_rss_mb()
            start = time.perf_counter()
            result = solve("kernel-matching", cat0, cat1)
            total = time.perf_counter() - start
        finally:
            if old is None:
                os.environ.pop("CORRLIB_CACHE_DIR")
            else:
                os.environ["CORRLIB_CACHE_DIR"] = old
    split = ", ".join(f"{k} {v:.2f} s" for k, v in result.timings.items() if k != "total")
    _line("kernel matching, complete pipeline, in process (cold cache)", total, split)
    print(f"peak resident memory: {peak_rss_mb():.0f} MB (before the run: {rss_before:.0f} MB)  [target <= 4 GB]")
    gt = {n: load_vts(resource(f"data/tosca/{n}.vts")) for n in ("cat0", "cat1", "cat1.sym")}
    report = geodesic_errors(result.map_xy, cat1, gt["cat0"], gt["cat1"], gt_target_sym=gt["cat1.sym"]).summary()
    print("accuracy: " + ", ".join(f"{k} {v:.3f}" for k, v in report.items()))
    if not quick:  # issue 19's figure: what the user waits for, on every bundled kind of pair
        tosca, sumner = resource("data/tosca"), resource("data/sumner")
        pairs = [(tosca / "cat0.off", tosca / "cat1.off"), (tosca / "cat1.off", tosca / "cat0.off"),
                 (tosca / "wolf0.off", tosca / "wolf1.off"),
                 (resource("people/human1.off"), resource("people/human2.off")),
                 (resource("people/human2.off"), resource("people/human1.off")),
                 (sumner / "lion-00.off", sumner / "cat-00.off"),
                 (sumner / "cat-00.off", sumner / "lion-00.off")]  # the larger source: the slowest bundled pair
        _cli_walls("kernel-matching", pairs, warm_too=True)
    # the assignment backends on kernel scores of the coarse scale
    s0, s1 = mesh_spectrum(cat0, 500), mesh_spectrum(cat1, 500)
    rng = np.random.default_rng(0)
    for n in ((1000,) if quick else (1000, 2000, 3000)):
        i0 = farthest_point_sampling(cat0.vertices, n)
        i1 = farthest_point_sampling(cat1.vertices, n)
        c = s1.evecs[i1[rng.permutation(n)]].T @ s0.evecs[i0]
        tau = 0.0259  # the first (largest) relative time of the default schedule
        score = kernel_score(s1.evecs[i1], s0.evecs[i0], c, np.exp(-tau * cat1.area * s1.evals),
                       np.exp(-tau * cat0.area * s0.evals))
        t_auction, sol = _best_time(lambda: linear_assignment(score), repeat)
        t_exact, ref = _best_time(lambda: linear_assignment(score, method="scipy"), 1)
        gap = (assignment_score(score, ref) - assignment_score(score, sol)) / float(np.ptp(score))
        _line(f"assignment {n} x {n} kernel score: auction", t_auction,
              f"scipy {t_exact:.2f} s, speed-up {t_exact / t_auction:.1f}x, objective gap {gap:.1e} of the range")


def suite_divfree(repeat: int, quick: bool = False) -> None:
    """Issue 5 targets: one EM iteration at N = K = 3000, T = 20; the whole match of a 5k pair; flowing
    10k / 30k / 100k vertices."""
    from corrlib.deformation.basis import DivFreeBasis
    from corrlib.deformation.flow import flow
    from corrlib.descriptors import mesh_descriptors
    from corrlib.evaluation import geodesic_errors
    from corrlib.io import load_mesh, load_vts
    from corrlib.methods import make_params, solve
    from corrlib.methods.divergence_free import DivergenceFreeParams, FlowLinearisation, em_iteration, prepare_fit
    from corrlib.progress import Stopwatch
    from corrlib.resources import resource

    cat0 = load_mesh(resource("data/tosca/cat0.off"))
    cat1 = load_mesh(resource("data/tosca/cat1.off"))
    print(f"machine: {os.cpu_count()} cores; pair: cat0 ({cat0.n_vertices} v) -> cat1 ({cat1.n_vertices} v)")
    params = make_params(DivergenceFreeParams)
    fx, fy = mesh_descriptors(cat0, "shot"), mesh_descriptors(cat1, "shot")
    sx, sy, feat_dist, frames, w = prepare_fit(cat0.vertices, cat1.vertices, fx, fy, params, Stopwatch())
    basis = DivFreeBasis(params.n_fields)
    start, targets = frames.source_to_cube(cat0.vertices[sx]), frames.target_to_cube(cat1.vertices[sy])
    coeffs = basis.random_coefficients(0.05, seed=0)
    precision = params.prior_weight / basis.prior_variance
    linearisation = FlowLinearisation(basis, start, params.n_steps)
    nudged = coeffs * 1.001  # the coefficient change of a secant iteration

    def iteration(exact):
        if not exact:  # the secant update starts from an exact derivative at ``coeffs`` (not timed)
            linearisation(coeffs, exact=True)
        watch = Stopwatch()
        start_time = time.perf_counter()
        em_iteration(linearisation, targets, w * feat_dist, coeffs if exact else nudged, params.sigma2, precision,
                     params, watch, exact=exact)
        return time.perf_counter() - start_time, watch.times

    FlowLinearisation(basis, start[:10], params.n_steps)(coeffs)  # compile
    splits = {exact: min((iteration(exact) for _ in range(max(repeat, 1))), key=lambda r: r[0])
              for exact in (True, False)}
    size = f"N = {len(sx)}, K = {basis.n_fields}, T = {params.n_steps}"
    for exact, name in ((True, "exact flow derivative"), (False, "secant update of the derivative")):
        seconds, times = splits[exact]
        _line(f"one EM iteration, {name}, {size}", seconds, ", ".join(f"{k} {v:.2f} s" for k, v in times.items()))
    every = params.jacobian_every
    mean = (splits[True][0] + (every - 1) * splits[False][0]) / every
    _line(f"EM iteration, mean of the default schedule (exact every {every})  [target <= 1.5 s]", mean)
    if not quick:
        rss_before = peak_rss_mb()
        start_time = time.perf_counter()
        result = solve("divergence-free", cat0, cat1)
        total = time.perf_counter() - start_time
        split = ", ".join(f"{k} {v:.2f} s" for k, v in result.timings.items() if k != "total")
        _line(f"divergence-free match cat0 -> cat1, {result.extras['iterations']} iterations, in process", total,
              split)
        print(f"peak resident memory: {peak_rss_mb():.0f} MB (before the run: {rss_before:.0f} MB)")
        gt = {n: load_vts(resource(f"data/tosca/{n}.vts")) for n in ("cat0", "cat1", "cat1.sym")}
        report = geodesic_errors(result.map_xy, cat1, gt["cat0"], gt["cat1"],
                                 gt_target_sym=gt["cat1.sym"]).summary()
        print("accuracy: " + ", ".join(f"{k} {v:.3f}" for k, v in report.items())
              + f"; volume change {result.extras['volume_change']:+.2e}")
        tosca = resource("data/tosca")
        _cli_walls("divergence-free", [(tosca / "cat0.off", tosca / "cat1.off")], warm_too=False)
    # flowing large meshes: midpoint subdivisions of wolf0 in the unit cube
    import trimesh

    wolf = load_mesh(resource("data/tosca/wolf0.off"))
    verts, faces = wolf.vertices, wolf.faces
    while len(verts) < 100_000:
        verts, faces = trimesh.remesh.subdivide(verts, faces)
    verts = (verts - verts.min(0)) / np.ptp(verts, axis=0).max() * 0.7 + 0.15
    flow(basis, verts[:100], coeffs, 1.0, params.n_steps)  # compile
    sizes = (10_000,) if quick else (10_000, 30_000, 100_000)
    for n in sizes:
        t_flow, _ = _best_time(lambda: flow(basis, verts[:n], coeffs, 1.0, params.n_steps), repeat)
        _line(f"flow {n} vertices to t = 1, K = {basis.n_fields}, T = {params.n_steps}  [100k: <= 5 s]", t_flow,
              f"{t_flow / n * 1e6:.1f} us per vertex")


def suite_product(repeat: int, quick: bool = False) -> None:
    """Issue 6 targets: localized harmonics on bands of two 500-point contours and of two ~1k-vertex meshes,
    and how the time grows with the band."""
    import trimesh
    from scipy.spatial import cKDTree

    from corrlib.geometry import product as pm
    from corrlib.io import load_contour
    from corrlib.resources import resource
    from corrlib.shapes import TriMesh

    a = load_contour(resource("data/silhouettes/mpeg7/dog-1.gif"), 500).points
    b = load_contour(resource("data/silhouettes/mpeg7/horse-1.gif"), 500).points
    fx, fy = pm.curve_factor(a, 100), pm.curve_factor(b, 100)
    for fraction in ((0.05,) if quick else (0.01, 0.02, 0.05, 0.1, 0.25)):
        width = int(round(fraction * 500))  # a band around the diagonal of the torus
        offsets = np.arange(width) - width // 2
        pairs = np.column_stack([np.repeat(np.arange(500), width), (np.arange(500)[:, None] + offsets).ravel() % 500])
        t, _ = _best_time(lambda: pm.localized_harmonics(fx, fy, pairs, 100), repeat)
        target = "  [target <= 5 s]" if fraction == 0.05 else ""
        _line(f"contours 500 x 500: 100 harmonics, {fraction:.0%} band ({len(pairs)} vertices){target}", t)

    def ellipsoid(count, stretch):
        s = trimesh.creation.uv_sphere(radius=1.0, count=count)
        return TriMesh.from_arrays(np.asarray(s.vertices) * stretch, np.asarray(s.faces), name="ellipsoid")

    stretch_x, stretch_y = np.array([1.0, 0.8, 0.6]), np.array([1.2, 0.7, 0.6])
    x, y = ellipsoid([23, 23], stretch_x), ellipsoid([24, 22], stretch_y)
    mx, my = pm.mesh_factor(x, 50), pm.mesh_factor(y, 50)
    map_xy = cKDTree(y.vertices / stretch_y).query(x.vertices / stretch_x)[1]
    print(f"meshes: two ellipsoids, {x.n_vertices} and {y.n_vertices} vertices")
    for fraction in ((0.01,) if quick else (0.005, 0.01, 0.02, 0.05, 0.1)):
        pairs = pm.largest_piece(mx, my, pm.band_around_map(map_xy, y.vertices, fraction))
        rss = peak_rss_mb()
        t, _ = _best_time(lambda: pm.localized_harmonics(mx, my, pairs, 200), 1)
        target = "  [target <= 60 s, 4 GB]" if fraction == 0.1 else ""
        _line(f"meshes ~1k x 1k: 200 harmonics, {fraction:.1%} band ({len(pairs)} vertices){target}", t,
              f"peak memory {peak_rss_mb():.0f} MB (before {rss:.0f} MB)")


def suite_bench(repeat: int, quick: bool = False) -> None:
    """Issue 8 targets: the runner's overhead per pair, and a kernel-matching benchmark on 5k pairs (20; ``quick``:
    4) in one worker limited to one core (the serial baseline), with ``--jobs 1`` and with ``--jobs 2``."""
    import shutil

    from corrlib.bench import Runner, load_dataset, parse_method, run_job
    from corrlib.parallel import process_pool
    from corrlib.resources import resource

    n_pairs = 4 if quick else 20
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "cats"
        (folder / "corres").mkdir(parents=True)
        copies = 5  # renamed copies of the two cats give distinct pairs
        for name in ("cat0", "cat1"):
            for c in range(copies):
                shutil.copy(resource(f"data/tosca/{name}.off"), folder / f"{name}{'abcde'[c]}.off")
                shutil.copy(resource(f"data/tosca/{name}.vts"), folder / "corres" / f"{name}{'abcde'[c]}.vts")
        pairs = [(f"cat0{a}", f"cat1{b}") for a in "abcde" for b in "abcde"][:n_pairs]
        (folder / "pairs.txt").write_text("".join(f"{a} {b}\n" for a, b in pairs))
        ds = load_dataset(folder)
        fast = [parse_method("descriptor-nn")]
        runner = Runner(ds, fast, Path(tmp) / "nn")
        start = time.perf_counter()
        runner.run(jobs=1)
        wall = time.perf_counter() - start
        recs = runner.records()
        overhead = np.median([r["overhead"] for r in recs])
        _line("runner overhead per pair, descriptor-nn maps (load + exact geodesic errors, 5k)", overhead,
              f"median over {len(recs)} pairs: loading {np.median([r['load_time'] for r in recs]):.3f} s, "
              f"evaluation {np.median([r['evaluation_time'] for r in recs]):.3f} s; whole run {wall:.1f} s")
        km = [parse_method("kernel-matching")]
        times = {}
        # the serial baseline of a parallel speed-up: the same jobs in one worker limited to one core (one
        # job of kernel matching already keeps two cores busy with its two starts, so --jobs 1 is no baseline)
        jobs_of_km = [job for _, job in Runner(ds, km, Path(tmp) / "km-one-core").pending()]
        run_job(jobs_of_km[0])  # the cats' spectra and descriptors cached first: no run below pays for them
        with process_pool(1, share=1) as pool:
            start = time.perf_counter()
            list(pool.map(run_job, jobs_of_km))
            times["one core"] = time.perf_counter() - start
        _line(f"kernel matching, {n_pairs} pairs of 5k, one worker limited to one core", times["one core"])
        for jobs in (1, 2):
            start = time.perf_counter()
            km_runner = Runner(ds, km, Path(tmp) / f"km{jobs}")
            km_runner.run(jobs=jobs)
            times[jobs] = time.perf_counter() - start
            _line(f"kernel matching, {n_pairs} pairs of 5k, --jobs {jobs}", times[jobs])
            if jobs == 1:
                recs = km_runner.records()
                _line("runner overhead per pair, kernel-matching maps  [target <= 0.5 s]",
                      float(np.median([r["overhead"] for r in recs])),
                      f"loading {np.median([r['load_time'] for r in recs]):.3f} s, exact evaluation "
                      f"{np.median([r['evaluation_time'] for r in recs]):.3f} s (grows with the map's errors)")
        print(f"speed-up of --jobs 2 over one core: {times['one core'] / times[2]:.2f}x  [target >= 1.7x]; "
              f"over --jobs 1: {times[1] / times[2]:.2f}x (one job already uses both cores)")


def suite_morph(repeat: int, quick: bool = False) -> None:
    """Sequences through a map: the as-rigid-as-possible interpolation's preparation and frames (the studio scrubs
    and exports them), on the wolves and on a subdivided copy; the volume half way against linear."""
    import trimesh

    from corrlib.deformation.rigid_interpolation import rigid_interpolation
    from corrlib.io import load_mesh
    from corrlib.resources import resource
    from corrlib.shapes import signed_volume

    wolf0, wolf1 = load_mesh(resource("data/tosca/wolf0.off")), load_mesh(resource("data/tosca/wolf1.off"))
    source, image, faces = wolf0.vertices, wolf1.vertices, wolf0.faces  # shared connectivity: the identity map
    for level in ((0,) if quick else (0, 1, 2)):
        if level:  # midpoint subdivision keeps the two poses on one connectivity
            source, faces_next = trimesh.remesh.subdivide(source, faces)
            image, _ = trimesh.remesh.subdivide(image, faces)
            faces = faces_next
        edges = faces[:, [0, 1]]
        resolution = float(np.mean(np.linalg.norm(image[edges[:, 0]] - image[edges[:, 1]], axis=1)))  # as morph does
        t_build, sequence = _best_time(lambda: rigid_interpolation(source, faces, image, resolution=resolution),
                                       repeat)
        times = np.linspace(0.0, 1.5, 16)
        t_frames = _best_time(lambda: [sequence.positions(t) for t in times], repeat)[0] / times.size
        mid = signed_volume(sequence.positions(0.5), faces)
        linear_mid = signed_volume(0.5 * (source + image), faces)
        reference = 0.5 * (signed_volume(source, faces) + signed_volume(image, faces))
        _line(f"as-rigid-as-possible interpolation wolf0 -> wolf1, {len(source)} vertices: preparation", t_build,
              f"one frame {1000 * t_frames:.1f} ms; volume half way {mid / reference:.3f} of the mean "
              f"(linear {linear_mid / reference:.3f})")


SUITES = {"foundation": suite_foundation, "contour3d": suite_contour3d, "kernel": suite_kernel,
          "divfree": suite_divfree, "product": suite_product, "bench": suite_bench, "morph": suite_morph}


def reference_workload_seconds(repeat: int = 3) -> float:
    """Best wall time of a fixed single-threaded workload: ten products of (800, 800) float64 matrices (the
    arithmetic of the spectra and kernel scores) and a sort of two million floats (memory-bound, like the
    assignments and searches).

    A shared machine's speed changes from hour to hour, often by more than the change a benchmark is run to
    measure (docs/decisions.md). Printed before a suite's figures, it lets figures of different hours be
    compared: each is to be read against the workload's time of its own run.
    """
    from threadpoolctl import threadpool_limits

    rng = np.random.default_rng(0)
    a, values = rng.standard_normal((800, 800)), rng.standard_normal(2_000_000)

    def workload():
        product = a
        for _ in range(10):
            product = (product @ a) / 800.0
        return np.sort(values)[0] + product[0, 0]

    with threadpool_limits(1):
        return _best_time(workload, repeat)[0]


def run_suite(name: str, repeat: int = 3, quick: bool = False) -> None:
    """Run a named benchmark suite (``quick``: a smoke run with fewer cases), after the machine's
    :func:`reference_workload_seconds`."""
    if name not in SUITES:
        raise ParameterError(f"unknown benchmark suite {name!r} (available: {', '.join(SUITES)})")
    _line("machine: reference workload, one thread (read the figures below against it)",
          reference_workload_seconds(1 if quick else 3))
    SUITES[name](repeat, quick)
