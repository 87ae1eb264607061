"""The warm-up compiles every numba kernel the methods use, with the argument types they use.

`scripts/setup.sh` runs :func:`corrlib.warmup.warm_up` so that the first run of a method after an
install does not compile (issue 19); the studio runs it in the background. A kernel the warm-up calls
with other types (e.g. writable where a mesh's arrays are read-only) would still compile at the first
real run: the methods must add no compiled signature after the warm-up.
"""

import json
import os
import subprocess
import sys
import textwrap

import pytest

from tests._data import ROOT, SILHOUETTES

SCRIPT = textwrap.dedent("""
    import importlib, json, pkgutil, sys
    import numpy as np
    from numba.core.registry import CPUDispatcher
    import corrlib

    def signatures():
        found = {}
        for info in pkgutil.walk_packages(corrlib.__path__, "corrlib."):
            if info.name.startswith("corrlib.app"):
                continue
            module = importlib.import_module(info.name)
            for name, value in vars(module).items():
                if isinstance(value, CPUDispatcher) and value.__module__ == info.name:
                    found[f"{info.name}.{name}"] = sorted(map(str, value.signatures))
        return found

    from corrlib.warmup import warm_up
    warm_up()
    before = signatures()
    from corrlib.io import load_contour, load_mesh
    from corrlib.methods import solve
    people = sys.argv[1]
    a, b = load_mesh(people + "/human0.off"), load_mesh(people + "/human1.off")
    solve("kernel-matching", a, b, n_eigs=60, n_seeds=300, n_times=2)
    solve("divergence-free", a, b, max_iter=2, n_samples=200, n_fields=60)
    solve("fmap-zoomout", a, b)
    outline = load_contour(sys.argv[2])
    solve("contour3d", outline, a, n_contour=60)
    solve("contour3d", outline, a, n_contour=30, energy="elastic")  # an energy the studio's form offers
    solve("contour-views", outline, a)
    from corrlib.progress import run
    from corrlib.retrieval import retrieve
    run(retrieve(outline, [people + "/human0.off"], jobs=1))  # ranked with the view dissimilarity (the default)
    after = signatures()
    print(json.dumps({name: sorted(set(sigs) - set(before.get(name, []))) for name, sigs in after.items()}))
""")


@pytest.mark.slow
def test_methods_compile_nothing_after_the_warm_up(tmp_path):
    # a private spectra cache, so that the descriptors are computed. Numba's own cache is the one the warm-up
    # fills (a fresh one would make this test compile everything, a minute): a signature loaded from it is added
    # to the dispatcher's signatures just as a compiled one is, so a type the warm-up misses is still seen
    # (test_a_signature_loaded_from_numbas_cache_counts_as_added checks that premise)
    env = {**os.environ, "CORRLIB_CACHE_DIR": str(tmp_path / "cache")}
    out = subprocess.run([sys.executable, "-c", SCRIPT, str(ROOT / "resources" / "people"),
                          str(SILHOUETTES / "horse.png")],
                         capture_output=True, text=True, env=env, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    added = json.loads(out.stdout.strip().splitlines()[-1])
    assert {name: sigs for name, sigs in added.items() if sigs} == {}


CACHED_KERNEL = textwrap.dedent("""
    import numba

    @numba.njit(cache=True)
    def add_one(x):
        return x + 1
""")

CALL_AND_REPORT = textwrap.dedent("""
    import json, sys
    import numpy as np
    sys.path.insert(0, sys.argv[1])
    import cached_kernel
    before = sorted(map(str, cached_kernel.add_one.signatures))
    cached_kernel.add_one(np.ones(3))
    after = sorted(map(str, cached_kernel.add_one.signatures))
    print(json.dumps({"before": before, "after": after, "hits": sum(cached_kernel.add_one.stats.cache_hits.values())}))
""")


def test_a_signature_loaded_from_numbas_cache_counts_as_added(tmp_path):
    (tmp_path / "cached_kernel.py").write_text(CACHED_KERNEL)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    runs = []
    for _ in range(2):  # the first run compiles and writes the cache, the second loads from it
        out = subprocess.run([sys.executable, "-c", CALL_AND_REPORT, str(tmp_path)], capture_output=True, text=True,
                             env=env, timeout=300)
        assert out.returncode == 0, out.stderr[-2000:]
        runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
    assert [r["hits"] for r in runs] == [0, 1]
    for run in runs:
        assert run["before"] == [] and len(run["after"]) == 1


def test_a_caller_s_own_writable_arrays_reach_the_kernels_as_the_meshes_do():
    """SHOT and the closest surface points take plain arrays; a writable array is another numba type than a
    mesh's read-only one, so each kernel compiled twice (at a fresh install's first call with the caller's
    array, after the warm-up). Handed through :func:`corrlib.shapes.readonly_view`, both reach one
    signature, and the caller's array stays writable."""
    import numpy as np

    from corrlib.descriptors import shot as shot_module
    from corrlib.geometry import lifting
    from corrlib.io import load_mesh
    from corrlib.shapes import readonly_view
    from tests._data import TOSCA

    mesh = load_mesh(TOSCA / "wolf0.off")
    own = np.array(mesh.vertices)  # writable, a caller's points
    normals = shot_module.vertex_normals(mesh.vertices, mesh.faces)
    assert own.flags.writeable and not mesh.vertices.flags.writeable
    view = readonly_view(own[:, ::-1], np.float64)  # not contiguous: a copy
    assert not view.flags.writeable and view.flags.c_contiguous and own.flags.writeable
    assert np.array_equal(view, own[:, ::-1])
    for points in (mesh.vertices, own):
        shot_module.shot(points, normals=normals, radius=0.05 * np.ptp(mesh.vertices, axis=0).max())
        lifting.closest_surface_points(points, mesh, np.zeros((len(points), 1), dtype=np.int64))
    assert len(shot_module._shot_all.signatures) == 1
    assert len(lifting._closest_in_stars.signatures) == 1
    assert own.flags.writeable
