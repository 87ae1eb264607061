"""Reference maps from pyFM's standard pipeline, for ``corr bench --maps pyfm=OUT``.

pyFM (PyPI ``pyfmaps``, MIT) is the public functional-maps implementation that
issue 18 measures ``fmap-zoomout`` against. It is a reference only, never a
dependency of the project: install it in a scratch environment and run this
script with that environment's interpreter::

    python3 -m venv /tmp/pyfm && /tmp/pyfm/bin/pip install pyfmaps
    /tmp/pyfm/bin/python scripts/pyfm_maps.py DATASET PAIRS OUT [--orientation W]
    corr bench DATASET --pairs PAIRS --maps pyfm=OUT --method fmap-zoomout

DATASET holds ``<name>.off`` meshes, PAIRS lines ``source target``. For every
pair the script writes ``OUT/<source>__<target>.txt``: the 0-based target
vertex of every source vertex, the format ``corr bench --maps`` reads. The
pipeline is pyFM's documented one: 100 WKS subsampled every 5th (20
functions), a 35 × 35 map fitted with pyFM's default weights (``--orientation``
sets its orientation term, default 0 as in its examples), ZoomOut to 100 in
steps of 5. Pairs already written are skipped, so a run resumes.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np


def read_pairs(dataset: Path, pairs: Path) -> list[tuple[str, str]]:
    """The ``(source, target)`` names of ``pairs``, every mesh checked to exist as ``dataset/<name>.off``.

    Raises ``ValueError`` naming the file and line of the first problem."""
    if not dataset.is_dir():
        raise ValueError(f"{dataset}: not a folder of meshes")
    try:
        lines = pairs.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{pairs}: cannot read the pairs file ({exc})") from None
    out = []
    for number, line in enumerate(lines, 1):
        if not line.strip():
            continue
        names = line.split()
        if len(names) != 2:
            raise ValueError(f"{pairs}, line {number}: expected 'source target', found {line.strip()!r}")
        for name in names:
            if not (dataset / f"{name}.off").is_file():
                raise ValueError(f"{pairs}, line {number}: {dataset / f'{name}.off'} does not exist")
        out.append((names[0], names[1]))
    if not out:
        raise ValueError(f"{pairs}: no pairs")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("dataset", type=Path)
    parser.add_argument("pairs", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--orientation", type=float, default=0.0, help="pyFM's w_orient (default 0)")
    args = parser.parse_args()
    try:
        pairs = read_pairs(args.dataset, args.pairs)
        args.out.mkdir(parents=True, exist_ok=True)
    except (ValueError, OSError) as exc:
        parser.error(str(exc))  # exit 2
    try:
        from pyFM.functional import FunctionalMapping
        from pyFM.mesh import TriMesh
    except ImportError:
        parser.error("pyFM is not installed in this interpreter: pip install pyfmaps in a scratch environment "
                     "and run the script with its python")
    for source, target in pairs:
        out = args.out / f"{source}__{target}.txt"
        if out.exists():
            continue
        start = time.perf_counter()
        partial = out.with_name(out.name + ".part")  # renamed when whole: a resumed run never skips half a map
        try:
            # pyFM's pointwise map goes from its second mesh to its first: the target first gives source -> target
            model = FunctionalMapping(TriMesh(str(args.dataset / f"{target}.off")),
                                      TriMesh(str(args.dataset / f"{source}.off")))
            model.preprocess(n_descr=100, subsample_step=5, descr_type="WKS")
            model.fit(K=(35, 35), w_orient=args.orientation)
            model.zoomout_refine(nit=13, step=5)
            np.savetxt(partial, model.get_p2p(), fmt="%d")
            os.replace(partial, out)
        except Exception as exc:  # pyFM's own errors (an unreadable mesh, a failed fit) and the disk's
            partial.unlink(missing_ok=True)
            parser.exit(2, f"{parser.prog}: error: {source} -> {target}: pyFM failed ({type(exc).__name__}: {exc}); "
                           f"the maps written so far are whole and a rerun resumes after them\n")
        print(f"{source} -> {target}: {time.perf_counter() - start:.1f} s", flush=True)


if __name__ == "__main__":
    sys.exit(main())
