"""Paths of the bundled demo data (``resources/`` at the top of the repository).

``$CORRLIB_RESOURCES`` overrides the location.
"""

from __future__ import annotations

import os
from pathlib import Path

from corrlib.errors import FileFormatError


def resource_dir() -> Path:
    """The ``resources`` folder."""
    env = os.environ.get("CORRLIB_RESOURCES")
    path = Path(env) if env else Path(__file__).resolve().parents[1] / "resources"
    if not path.is_dir():
        raise FileFormatError(f"bundled resources not found at {path} (set CORRLIB_RESOURCES)")
    return path


def resource(relative: str) -> Path:
    """Path of a bundled file, e.g. ``resource("data/tosca/wolf0.off")``."""
    path = resource_dir() / relative
    if not path.exists():
        raise FileFormatError(f"bundled resource {relative!r} not found in {resource_dir()}")
    return path


#: the demo pair: same connectivity, different pose (identity ground truth)
DEMO_PAIR = ("data/tosca/wolf0.off", "data/tosca/wolf1.off")


def bundled_shapes() -> list[tuple[str, str]]:
    """(label, relative path) of the bundled meshes and silhouettes, for the studio's shape panel."""
    root = resource_dir()
    out = []
    for pattern in ("data/tosca/*.off", "data/sumner/*.off", "data/sketch2d/*.off", "data/silhouettes/*.png",
                    "data/silhouettes/mpeg7/*.gif", "data/silhouettes/drawn/*.txt"):
        for path in sorted(root.glob(pattern)):
            rel = path.relative_to(root).as_posix()
            out.append((rel.removeprefix("data/"), rel))
    return out


#: the retrieval collection of the studio's "Try retrieval": collection name -> bundled mesh (4 classes)
RETRIEVAL_COLLECTION = {
    "cat0.off": "data/tosca/cat0.off", "cat1.off": "data/tosca/cat1.off", "cat2.off": "data/sumner/cat-00.off",
    "wolf0.off": "data/tosca/wolf0.off", "wolf1.off": "data/tosca/wolf1.off", "lion0.off": "data/sumner/lion-00.off",
    **{f"human{i}.off": f"people/human{i}.off" for i in range(4)}}
#: the query it starts with: the hand-drawn person of the CVPR 2016 paper (the people should rank first)
RETRIEVAL_QUERY = "data/sketch2d/human_sketch_a_contour.txt"


def retrieval_collection(folder=None) -> Path:
    """A folder holding the bundled retrieval collection, named so that a file's class is its name's stem.

    The files are links to the bundled meshes (copies where links are not possible), made once in
    ``folder`` (default: a folder in the system's temporary directory).
    """
    import shutil
    import tempfile

    if folder is None:  # one folder per resources folder, so that every link points into this installation
        import hashlib

        tag = hashlib.sha1(str(resource_dir()).encode()).hexdigest()[:10]
        folder = Path(tempfile.gettempdir()) / f"corrlib-retrieval-collection-{tag}"
    target = Path(folder)
    target.mkdir(parents=True, exist_ok=True)
    for name, relative in RETRIEVAL_COLLECTION.items():
        link = target / name
        if link.exists():
            continue
        if link.is_symlink():  # a link whose file has gone
            link.unlink()
        source = resource(relative)
        try:
            link.symlink_to(source)
        except OSError:
            shutil.copyfile(source, link)
    return target

