"""Build the sketch-retrieval benchmark set used in docs/decisions.md (``corr bench-retrieval``).

``python scripts/retrieval_set.py OUT`` writes ``OUT/collection`` (the
studio's bundled retrieval collection, ``corrlib.resources.retrieval_collection``:
10 meshes of 4 classes, the bundled cats, wolves and lion and the four poses
of the synthetic person in ``resources/people``) and ``OUT/queries``
(21 queries, class = file name without its number):

* the side view and the top view of each of the 6 animal meshes, rendered
  (outline of the orthographic projection along the least and the middle
  principal axis);
* the front view of the rest pose and of the fourth pose of the person;
* the two bundled human sketches (``resources/data/sketch2d``);
* two MPEG-7 silhouettes of classes the collection holds: ``children-1``
  (a person) and ``dog-1`` (counted as the wolf class, the collection's
  canine);
* three outlines drawn by hand as polygons (a cat and a wolf from the side,
  a person from the front), as a user would click them.

Then: ``corr bench-retrieval OUT/queries OUT/collection``.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np


#: hand-drawn polygons (x, y), closed by repeating the first point
DRAWN = {
    "cat": [(0, 7.5), (-2, 10), (-2.5, 9.8), (-0.3, 7), (0, 4), (0.6, 4), (0.6, 0), (1.4, 0), (1.4, 3.8),
            (2.2, 3.8), (2.2, 0), (3, 0), (3, 4), (7, 4), (7, 0), (7.8, 0), (7.8, 3.8), (8.6, 3.8), (8.6, 0),
            (9.4, 0), (9.4, 4.2), (10, 5.5), (11.5, 5.8), (12, 7), (11.6, 8.2), (11.6, 9.2), (11.1, 8.6),
            (10.6, 8.6), (10.2, 9.2), (10.1, 8.1), (9.4, 7.2)],
    "human": [(0, 0), (1, 0), (1.3, 4), (1.7, 0), (2.7, 0), (2.4, 5), (2.6, 8), (3.8, 5.5), (4.4, 5.8), (3, 9.2),
              (2.4, 9.6), (2.1, 9.8), (2.4, 10.4), (2.2, 11.3), (1.35, 11.6), (0.5, 11.3), (0.3, 10.4), (0.6, 9.8),
              (0.3, 9.6), (-0.3, 9.2), (-1.7, 5.8), (-1.1, 5.5), (0.1, 8), (0.3, 5)],
    "wolf": [(0, 6), (-3, 4.5), (-3.2, 5.2), (-0.2, 7), (0.5, 7.2), (8, 7.2), (9, 8), (9.3, 9), (9.6, 8.3), (10, 8.1),
             (12.2, 7.3), (12.2, 6.8), (10, 6.4), (9.3, 5), (9.2, 4), (9.2, 0), (8.4, 0), (8.4, 3.8), (7.8, 3.8),
             (7.8, 0), (7, 0), (7, 4), (2.5, 4), (2.5, 0), (1.7, 0), (1.7, 3.8), (1.1, 3.8), (1.1, 0), (0.3, 0),
             (0.3, 4)],
}
def _fail(message: str) -> None:
    print(f"error: {message}", file=sys.stderr)
    sys.exit(2)


def main(out: Path) -> None:
    from corrlib.contour_bench import principal_frame, silhouette_query
    from corrlib.errors import CorrError
    from corrlib.geometry.sections import render_silhouette
    from corrlib.io import ensure_output_folder, load_mesh
    from corrlib.resources import resource, retrieval_collection

    collection, queries = out / "collection", out / "queries"
    for folder in (collection, queries):
        if folder.is_dir() and any(folder.iterdir()):
            _fail(f"{folder} is not empty; choose a new output folder")
        try:
            ensure_output_folder(folder)
        except CorrError as exc:
            _fail(str(exc))
    retrieval_collection(collection)

    count = 0

    def write(points, label, suffix=".txt", source=None):
        nonlocal count
        count += 1
        target = queries / f"{label}_{count:02d}{suffix}"
        if source is None:
            np.savetxt(target, points)
        else:
            shutil.copy(source, target)

    for name in ("cat0", "cat1", "cat2", "wolf0", "wolf1", "lion0"):
        mesh = load_mesh(collection / f"{name}.off")
        label = name.rstrip("0123456789")
        write(silhouette_query(mesh).contour.points, label)
        _, axes = principal_frame(mesh)
        write(render_silhouette(mesh, axes[1], 256, up=axes[0]).points, label)
    for name in ("human0", "human3"):
        write(silhouette_query(load_mesh(collection / f"{name}.off")).contour.points, "human")
    for sketch in "ab":
        write(None, "human", source=resource(f"data/sketch2d/human_sketch_{sketch}_contour.txt"))
    write(None, "human", ".gif", resource("data/silhouettes/mpeg7/children-1.gif"))
    write(None, "wolf", ".gif", resource("data/silhouettes/mpeg7/dog-1.gif"))
    for label, polygon in DRAWN.items():
        write(np.array(polygon + polygon[:1], dtype=float), label)
    print(f"{len(list(collection.iterdir()))} meshes in {collection}, {count} queries in {queries}")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        _fail("usage: python scripts/retrieval_set.py OUT")
    main(Path(sys.argv[1]))
