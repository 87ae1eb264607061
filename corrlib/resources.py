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
                    "data/silhouettes/mpeg7/*.gif"):
        for path in sorted(root.glob(pattern)):
            rel = path.relative_to(root).as_posix()
            out.append((rel.removeprefix("data/"), rel))
    return out
