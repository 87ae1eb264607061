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
    after = signatures()
    print(json.dumps({name: sorted(set(sigs) - set(before.get(name, []))) for name, sigs in after.items()}))
""")


@pytest.mark.slow
def test_methods_compile_nothing_after_the_warm_up(tmp_path):
    # nothing read from caches: the descriptors are computed, and every kernel compiled for exactly the types
    # it is called with (a kernel cached on disk for other types could otherwise stand in)
    env = {**os.environ, "CORRLIB_CACHE_DIR": str(tmp_path / "cache"), "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    out = subprocess.run([sys.executable, "-c", SCRIPT, str(ROOT / "resources" / "people"),
                          str(SILHOUETTES / "horse.png")],
                         capture_output=True, text=True, env=env, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    added = json.loads(out.stdout.strip().splitlines()[-1])
    assert {name: sigs for name, sigs in added.items() if sigs} == {}
