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
* the three outlines drawn by hand as polygons (a cat and a wolf from the
  side, a person from the front), as a user would click them
  (``resources/data/silhouettes/drawn``).

``OUT/sources.txt`` names the mesh of each rendered query (``QUERY MESH`` per line). Then: ``corr
bench-retrieval OUT/queries OUT/collection``, with ``--own-meshes OUT/sources.txt`` to score the rendered
queries also with their own mesh left out (an outline against its shape's other poses).

``python scripts/retrieval_set.py --drawn OUT`` writes the same collection and, as queries, the seven outlines
of ``resources/data/silhouettes/drawn_set`` (two cats, a wolf, a lion, three people), drawn before any ranking
of them was seen (``docs/decisions.md``, sixty-fourth session): a check of retrieval on drawings that no choice
of the ranking was compared on, which the three drawings above were.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np


def _fail(message: str) -> None:
    print(f"error: {message}", file=sys.stderr)
    sys.exit(2)


def new_benchmark_folders(out: Path) -> tuple[Path, Path]:
    """``OUT/collection`` (the bundled retrieval collection) and an empty ``OUT/queries``; exits with a named
    error where either exists and is not empty or cannot be written."""
    from corrlib.errors import CorrError
    from corrlib.io import ensure_output_folder
    from corrlib.resources import retrieval_collection

    collection, queries = out / "collection", out / "queries"
    for folder in (collection, queries):
        if folder.is_dir() and any(folder.iterdir()):
            _fail(f"{folder} is not empty; choose a new output folder")
        try:
            ensure_output_folder(folder)
        except CorrError as exc:
            _fail(str(exc))
    retrieval_collection(collection)
    return collection, queries


def main(out: Path) -> None:
    from corrlib.contour_bench import silhouette_query
    from corrlib.io import load_mesh
    from corrlib.resources import resource

    collection, queries = new_benchmark_folders(out)

    count = 0
    sources = []  # "QUERY MESH" of every query rendered from a mesh of the collection

    def write(points, label, suffix=".txt", source=None, mesh=None):
        nonlocal count
        count += 1
        target = queries / f"{label}_{count:02d}{suffix}"
        if source is None:
            np.savetxt(target, points)
        else:
            shutil.copy(source, target)
        if mesh is not None:
            sources.append(f"{target.name} {mesh}.off")

    for name in ("cat0", "cat1", "cat2", "wolf0", "wolf1", "lion0"):
        mesh = load_mesh(collection / f"{name}.off")
        label = name.rstrip("0123456789")
        write(silhouette_query(mesh).contour.points, label, mesh=name)
        write(silhouette_query(mesh, 256, view="top").contour.points, label, mesh=name)
    for name in ("human0", "human3"):
        write(silhouette_query(load_mesh(collection / f"{name}.off")).contour.points, "human", mesh=name)
    for sketch in "ab":
        write(None, "human", source=resource(f"data/sketch2d/human_sketch_{sketch}_contour.txt"))
    write(None, "human", ".gif", resource("data/silhouettes/mpeg7/children-1.gif"))
    write(None, "wolf", ".gif", resource("data/silhouettes/mpeg7/dog-1.gif"))
    for label in ("cat", "human", "wolf"):
        write(None, label, source=resource(f"data/silhouettes/drawn/{label}.txt"))
    (out / "sources.txt").write_text("".join(f"{line}\n" for line in sources))
    print(f"{len(list(collection.iterdir()))} meshes in {collection}, {count} queries in {queries}; "
          f"{out / 'sources.txt'} names the mesh each rendered query was made from (corr bench-retrieval "
          f"--own-meshes)")


def drawings() -> list[Path]:
    """The outlines of ``resources/data/silhouettes/drawn_set``, each named ``CLASS_WHAT.txt``."""
    from corrlib.resources import resource

    return sorted(Path(resource("data/silhouettes/drawn_set")).glob("*.txt"))


def drawn_main(out: Path) -> None:
    """``--drawn OUT``: the bundled collection and the drawn set as queries, in a subfolder per class
    (``OUT/queries/cat/cat_walking.txt``), so that every query keeps the name of its drawing."""
    _, queries = new_benchmark_folders(out)
    for drawing in drawings():
        (queries / drawing.stem.split("_")[0]).mkdir(exist_ok=True)
        shutil.copy(drawing, queries / drawing.stem.split("_")[0] / drawing.name)
    print(f"{len(drawings())} drawn queries in {queries}, a subfolder per class; the bundled collection in "
          f"{out / 'collection'}")


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--drawn":
        drawn_main(Path(sys.argv[2]))
    elif len(sys.argv) == 2 and not sys.argv[1].startswith("-"):
        main(Path(sys.argv[1]))
    else:
        _fail("usage: python scripts/retrieval_set.py [--drawn] OUT")
