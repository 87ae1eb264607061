"""Build a view-robustness retrieval set: every mesh of the bundled collection seen from six directions.

``python scripts/retrieval_views.py OUT`` writes ``OUT/collection`` (the studio's bundled retrieval
collection, as ``scripts/retrieval_set.py``) and ``OUT/queries``: the outline of each mesh's orthographic
projection seen from

* azimuth 0°, 30° and 60° about the vertical axis, from the side view (along the axis of least variance)
  towards the other horizontal axis (a quadruped's length: 90° would look at its head; a person's width:
  90° would be a profile), at elevation 0°, and
* azimuth 0° at elevation 30° and 60° (tilted towards the vertical axis: 90° would be a top view), and
  azimuth 30° at elevation 30°.

The vertical axis is the mesh's principal axis of middle variance (a quadruped's height) and, for the
class ``human``, of largest variance (a standing person's height). Queries are named ``CLASS_NN.txt``
(``corr bench-retrieval`` reads the class from the name); ``OUT/views.txt`` says which mesh and view each
one is. Then: ``corr bench-retrieval OUT/queries OUT/collection --own-meshes OUT/views.txt`` (every query also
scored with the mesh it was rendered from left out of its ranking).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

#: (azimuth, elevation) in degrees, see the module docstring
VIEWS = ((0, 0), (30, 0), (60, 0), (0, 30), (30, 30), (0, 60))
#: principal axis (0: largest variance) that is vertical, per class; other classes: 1
VERTICAL_AXIS = {"human": 0}
#: pixels along the longer side of a rendered outline (the retrieval set's top views use the same)
RESOLUTION = 256


def _retrieval_set():
    """``scripts/retrieval_set.py`` as a module (its folders and its error exit), imported when the script runs
    (not when a test imports :func:`view_direction`, so that importing this file leaves ``sys.path`` alone)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("retrieval_set", Path(__file__).resolve().parent / "retrieval_set.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def view_direction(axes: np.ndarray, vertical: int, azimuth: float, elevation: float) -> np.ndarray:
    """(3,) unit viewing direction: the least-variance axis turned by ``azimuth`` degrees about the vertical
    principal axis ``axes[vertical]`` towards the other horizontal one, then by ``elevation`` towards the
    vertical."""
    horizontal = [i for i in (0, 1) if i != vertical][0]
    az, el = np.radians(azimuth), np.radians(elevation)
    level = np.cos(az) * axes[2] + np.sin(az) * axes[horizontal]
    return np.cos(el) * level + np.sin(el) * axes[vertical]


def main(out: Path) -> None:
    from corrlib.geometry.sections import principal_frame
    from corrlib.geometry.sections import render_silhouette
    from corrlib.io import load_mesh, save_contour
    from corrlib.retrieval import class_of

    collection, queries = _retrieval_set().new_benchmark_folders(out)
    lines = []
    for path in sorted(collection.glob("*.off")):
        mesh = load_mesh(path)
        _, axes = principal_frame(mesh)
        label = class_of(path)
        vertical = VERTICAL_AXIS.get(label, 1)
        for azimuth, elevation in VIEWS:
            direction = view_direction(axes, vertical, azimuth, elevation)
            contour = render_silhouette(mesh, direction, RESOLUTION, up=axes[vertical])
            name = f"{label}_{len(lines) + 1:02d}.txt"
            save_contour(queries / name, contour)
            lines.append(f"{name} {path.name} azimuth {azimuth} elevation {elevation}")
    (out / "views.txt").write_text("\n".join(lines) + "\n")
    print(f"{len(lines)} queries in {queries} ({len(VIEWS)} views of each of the {len(lines) // len(VIEWS)} meshes "
          f"in {collection}); {out / 'views.txt'} names them")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        _retrieval_set()._fail("usage: python scripts/retrieval_views.py OUT")
    main(Path(sys.argv[1]))
