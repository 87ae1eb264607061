"""Build a retrieval set of outlines drawn by hand: ``resources/data/silhouettes/drawn_set`` against the collection.

``python scripts/retrieval_drawn.py OUT`` writes ``OUT/collection`` (the studio's bundled retrieval collection,
as ``scripts/retrieval_set.py``) and ``OUT/queries``: the seven polygons of ``drawn_set`` (two cats, a wolf, a
lion, three people; ``resources/data/PROVENANCE.md``), each named ``CLASS_NN.txt`` (``corr bench-retrieval``
reads the class from the name, the drawing's from the part of its file name before the first ``_``).
``OUT/drawings.txt`` says which drawing each query is. Then: ``corr bench-retrieval OUT/queries OUT/collection``.

The drawings were made before any ranking of them was seen (``docs/decisions.md``, sixty-fourth session), as a
check of retrieval on queries that no choice of the method was compared on; ``scripts/retrieval_set.py``'s
three drawings are the ones the ranking rules were chosen with.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path


def _retrieval_set():
    """``scripts/retrieval_set.py`` as a module (its folders and its error exit)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("retrieval_set", Path(__file__).resolve().parent / "retrieval_set.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def drawings() -> list[Path]:
    """The drawn outlines, in the order of their query numbers."""
    from corrlib.resources import resource

    return sorted(Path(resource("data/silhouettes/drawn_set")).glob("*.txt"))


def main(out: Path) -> None:
    _, queries = _retrieval_set().new_benchmark_folders(out)
    lines = []
    for number, drawing in enumerate(drawings(), start=1):
        name = f"{drawing.stem.split('_')[0]}_{number:02d}.txt"
        shutil.copy(drawing, queries / name)
        lines.append(f"{name} {drawing.name}")
    (out / "drawings.txt").write_text("\n".join(lines) + "\n")
    print(f"{len(lines)} drawn queries in {queries}, the bundled collection in {out / 'collection'}; "
          f"{out / 'drawings.txt'} names them")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        _retrieval_set()._fail("usage: python scripts/retrieval_drawn.py OUT")
    main(Path(sys.argv[1]))
