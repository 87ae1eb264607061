"""On-disk cache of numpy arrays keyed by content (e.g. spectra of a mesh).

The cache lives in ``$CORRLIB_CACHE_DIR`` (default ``~/.cache/corrlib``);
set ``CORRLIB_CACHE_DIR=off`` to disable it. Entries are ``.npz`` files
written atomically (temporary file + rename), loaded without pickle, so a
crashed writer never leaves a half-written entry and concurrent processes
(parallel retrieval) can share the cache.

An entry is trusted only if it is the one asked for: it holds its own key, and every array has the dtype,
shape and range its reader declares (:class:`Array`). Anything else (another entry copied into its place,
values that are not finite, indices out of range, a file of another format) is dropped and recomputed. A
cache folder that cannot be searched (no permission, a name too long) is said once and not used.
"""

from __future__ import annotations

from dataclasses import dataclass
import hashlib
import os
import sys
import tempfile
import zipfile
import zlib
from pathlib import Path

import numpy as np

#: the array under which every entry stores its own key
KEY_FIELD = "cache_key"

#: cache folders found unusable in this process (each said once)
_UNUSABLE: set[str] = set()


@dataclass(frozen=True)
class Array:
    """What a reader expects of one array of an entry.

    ``kind``: ``"f"`` (floating point, every value finite) or ``"i"`` (integers ``>= 0``). ``shape``: one item
    per dimension — an int (that length), a name (the same length wherever the entry uses the name) or None
    (any length). ``below``: integers must be less than this int, or than the length of this named dimension.
    """

    kind: str
    shape: tuple
    below: int | str | None = None


def cache_dir() -> Path | None:
    """The cache folder, or ``None`` when caching is disabled."""
    value = os.environ.get("CORRLIB_CACHE_DIR", "")
    if value.lower() in {"off", "0", "none", "false"}:
        return None
    return Path(value).expanduser() if value else Path.home() / ".cache" / "corrlib"


def make_key(*parts) -> str:
    """SHA-1 hex key of the string forms of ``parts``."""
    h = hashlib.sha1()
    for part in parts:
        h.update(str(part).encode())
        h.update(b"\0")
    return h.hexdigest()


def _unusable(root: Path, exc: OSError) -> None:
    """Says once per folder that the cache cannot be used, and why."""
    if str(root) not in _UNUSABLE:
        _UNUSABLE.add(str(root))
        reason = (exc.strerror or str(exc)).lower()
        print(f"warning: the cache folder {root} cannot be used ({reason}); working without it (set "
              "CORRLIB_CACHE_DIR to another folder, or to off)", file=sys.stderr)


def _dims_agree(shape: tuple, expected: tuple, dims: dict) -> bool:
    if len(shape) != len(expected):
        return False
    for length, want in zip(shape, expected):
        if isinstance(want, int) and length != want:
            return False
        if isinstance(want, str) and dims.setdefault(want, length) != length:
            return False
    return True


def conforms(arrays: dict[str, np.ndarray], schema: dict[str, Array]) -> bool:
    """Whether ``arrays`` holds every array of ``schema`` with its dtype, shape and range."""
    dims: dict[str, int] = {}
    for name, spec in schema.items():
        value = arrays.get(name)
        if value is None or not _dims_agree(value.shape, spec.shape, dims):
            return False
        if spec.kind == "f" and not (np.issubdtype(value.dtype, np.floating) and np.all(np.isfinite(value))):
            return False
        if spec.kind == "i":
            if not np.issubdtype(value.dtype, np.integer) or (value.size and value.min() < 0):
                return False
    for name, spec in schema.items():  # the bounds once every named length is known
        bound = dims.get(spec.below) if isinstance(spec.below, str) else spec.below
        if spec.kind == "i" and bound is not None and arrays[name].size and arrays[name].max() >= bound:
            return False
    return True


def _drop(path: Path) -> None:
    try:
        path.unlink()
    except OSError:
        pass


def _read_npz(path: Path) -> dict[str, np.ndarray]:
    data = np.load(path, allow_pickle=False)
    if not isinstance(data, np.lib.npyio.NpzFile):  # a lone .npy array under the entry's name
        raise ValueError(f"{path} is not an .npz archive")
    with data:
        return {name: data[name] for name in data.files}


def load(kind: str, key: str, schema: dict[str, Array]) -> dict[str, np.ndarray] | None:
    """The arrays of ``schema`` stored under ``kind/key``, or ``None`` if absent, unreadable or not the entry
    asked for (:func:`conforms`, and its stored key); such an entry is dropped, except one that this user may
    not read (another user's, in a shared cache)."""
    root = cache_dir()
    if root is None or str(root) in _UNUSABLE:
        return None
    path = root / kind / f"{key}.npz"
    try:
        present = path.is_file()
    except OSError as exc:  # the folder itself: searched without permission, a name too long
        _unusable(root, exc)
        return None
    if not present:
        return None
    try:
        arrays = _read_npz(path)
    except PermissionError:
        return None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error):
        _drop(path)
        return None
    stored = arrays.get(KEY_FIELD)
    if stored is None or stored.shape != () or str(stored) != key or not conforms(arrays, schema):
        _drop(path)
        return None
    return {name: arrays[name] for name in schema}


def store(kind: str, key: str, arrays: dict[str, np.ndarray]) -> None:
    """Store arrays under ``kind/key`` atomically, with the key; failures to write are ignored (it is a cache),
    and never leave a temporary file behind."""
    root = cache_dir()
    if root is None or str(root) in _UNUSABLE:
        return
    folder = root / kind
    tmp = None
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=folder, suffix=".tmp")
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, **arrays, **{KEY_FIELD: np.array(key)})
        os.replace(tmp, folder / f"{key}.npz")
        tmp = None
    except OSError:
        return
    finally:
        if tmp is not None:  # a failed or interrupted write
            _drop(Path(tmp))
