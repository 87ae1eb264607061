"""On-disk cache of numpy arrays keyed by content (e.g. spectra of a mesh).

The cache lives in ``$CORRLIB_CACHE_DIR`` (default ``~/.cache/corrlib``);
set ``CORRLIB_CACHE_DIR=off`` to disable it. Entries are ``.npz`` files
written atomically (temporary file + rename), loaded without pickle, so a
crashed writer never leaves a half-written entry and concurrent processes
(parallel retrieval) can share the cache.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import zipfile
import zlib
from pathlib import Path

import numpy as np


def cache_dir() -> Path | None:
    """The cache folder, or ``None`` when caching is disabled."""
    value = os.environ.get("CORRLIB_CACHE_DIR", "")
    if value.lower() in {"off", "0", "none", "false"}:
        return None
    path = Path(value) if value else Path.home() / ".cache" / "corrlib"
    return path


def make_key(*parts) -> str:
    """SHA-1 hex key of the string forms of ``parts``."""
    h = hashlib.sha1()
    for part in parts:
        h.update(str(part).encode())
        h.update(b"\0")
    return h.hexdigest()


def load(kind: str, key: str) -> dict[str, np.ndarray] | None:
    """Arrays stored under ``kind/key``, or ``None`` if absent or unreadable."""
    root = cache_dir()
    if root is None:
        return None
    path = root / kind / f"{key}.npz"
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            return {name: data[name] for name in data.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error):
        # a corrupt entry is dropped, never trusted
        try:
            path.unlink()
        except OSError:
            pass
        return None


def store(kind: str, key: str, arrays: dict[str, np.ndarray]) -> None:
    """Store arrays under ``kind/key`` atomically; failures to write are ignored (it is a cache)."""
    root = cache_dir()
    if root is None:
        return
    folder = root / kind
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=folder, suffix=".tmp")
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, **arrays)
        os.replace(tmp, folder / f"{key}.npz")
    except OSError:
        return
