"""Writing outputs safely: atomic files, all-or-nothing sets, output locations checked before any work.

Every writer of the library goes through here: :func:`atomic_write` writes a temporary file in the
destination folder and renames it, :func:`staged_output` moves a whole set of files in at once (and removes
what it replaces), and :func:`check_output_file`, :func:`ensure_output_folder` and
:func:`check_outputs_apart` refuse, before a command does its work, an output it could not write or one that
would destroy an input. Re-exported by :mod:`corrlib.io`.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

from corrlib.errors import CorrError, InputError


def os_reason(exc: OSError) -> str:
    """The reason of a failed file operation, for a message (e.g. "permission denied")."""
    return (exc.strerror or str(exc)).lower()


@contextlib.contextmanager
def atomic_write(path, mode: str = "w"):
    """Context manager yielding a file object; the file appears at ``path`` only on success.

    Raises
    ------
    InputError
        Naming ``path`` when it cannot be written (permissions, a full disk, a file where a folder should be).
    """
    path = Path(path)
    _make_folder(path.parent, "output")
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as exc:
        raise InputError(f"{path}: cannot write the file ({os_reason(exc)})") from None
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600 files; exports get the usual permissions
    # text as UTF-8 whatever the locale, and a file name that is not UTF-8 written back as its own bytes
    text = {} if "b" in mode else {"encoding": "utf-8", "errors": "surrogateescape"}
    try:
        with os.fdopen(fd, mode, **text) as fh:
            yield fh
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            raise InputError(f"{path}: cannot write the file ({os_reason(exc)})") from None
        raise


#: what :func:`atomic_write` adds to a file's name while it writes it: a leading dot, then a dot, the 8 random
#: characters of ``tempfile.mkstemp`` and ``.tmp`` after it
TEMPORARY_NAME_EXTRA = 1 + 1 + 8 + len(".tmp")


def longest_file_name(folder: Path) -> int:
    """The longest file name, in bytes, that :func:`atomic_write` can write in ``folder`` (the file system's
    limit less its temporary name's extra characters; 255 where the folder does not say)."""
    probe = folder
    while not probe.is_dir() and probe != probe.parent:  # the nearest existing folder: on the same file system
        probe = probe.parent
    try:
        longest = os.pathconf(probe, "PC_NAME_MAX")
    except (OSError, ValueError):
        longest = 255
    return longest - TEMPORARY_NAME_EXTRA


def check_output_file(path, what: str = "output") -> Path:
    """Check, before any work, that a file can be written at ``path`` (its folder is created).

    Raises
    ------
    InputError
        Naming ``path``: empty, a folder, under a file, or in a folder that cannot be written.
    """
    if str(path).strip() == "" or Path(path).name in ("", ".", ".."):
        raise InputError(f"the {what} path {str(path)!r} does not name a file")
    if str(path).endswith(("/", os.sep)):  # Path() drops the separator that says "a folder"
        raise InputError(f"{path}: the {what} path ends with a separator, so it names a folder; expected a file "
                         f"name")
    path = Path(path)
    lost = lost_working_folder(path)
    if lost:
        raise InputError(f"{path}: cannot write {what} there{lost}")
    try:
        is_folder = path.is_dir()
    except OSError as exc:  # a folder on the way cannot be entered
        raise InputError(f"{path}: cannot write {what} there ({os_reason(exc)})") from None
    if is_folder:
        raise InputError(f"{path}: the {what} path is a folder, expected a file name")
    ensure_output_folder(path.parent, what)
    longest = longest_file_name(path.parent)
    if len(os.fsencode(path.name)) > longest:
        raise InputError(f"{path}: the {what} file name is {len(os.fsencode(path.name))} bytes long; its folder "
                         f"takes names of at most {longest} bytes here")
    return path


def check_outputs_apart(outputs, inputs) -> None:
    """Check, before any work, that no output file is one of the command's input files and that no two outputs
    are one file: the command would destroy its input, or one output would silently replace the other.

    Parameters
    ----------
    outputs : iterable of (str, path)
        What names each output (an option, e.g. ``"-o"``) and the file it goes to.
    inputs : iterable of (str, path or None)
        What names each input and its path; None, or a path that is not an existing file (a method's name given
        where a file could be), is skipped.

    Raises
    ------
    InputError
        Naming the file and both roles.
    """
    def same(a: Path, b: Path) -> bool:
        try:
            return os.path.samefile(a, b)
        except OSError:  # one of them does not exist (yet): compare where they would be
            return a.resolve() == b.resolve()

    existing = [(what, Path(path)) for what, path in inputs if path is not None and Path(path).is_file()]
    seen: list[tuple[str, Path]] = []
    for what, path in outputs:
        path = Path(path)
        for role, given in existing:
            if same(path, given):
                raise InputError(f"{path}: the output of {what} is the input file given as {role}; writing it "
                                 "would destroy the input, choose another output path")
        for other, earlier in seen:
            if same(path, earlier):
                raise InputError(f"{path}: {other} and {what} would both write this file; give them different "
                                 "paths")
        seen.append((what, path))


def check_outside(out, folder, what: str, role: str) -> None:
    """Refuse an output folder ``out`` that is ``folder`` or lies inside it, where a command reads every file of
    ``folder`` (its ``role``, e.g. the queries): the next run would read the outputs as inputs.

    Raises
    ------
    InputError
        Naming both folders.
    """
    try:
        out_path, folder_path = Path(out).resolve(), Path(folder).resolve()
    except OSError:  # no working folder to resolve against: the folder checks name that
        return
    if out_path == folder_path or folder_path in out_path.parents:
        raise InputError(f"{out}: the {what} folder is inside {folder}, the folder of {role}; the next run would read "
                         f"its files as {role}, choose a folder outside it")


@contextlib.contextmanager
def staged_output(folder, replaces=None):
    """Write a set of files all-or-nothing into ``folder`` (a generator-based context manager).

    Yields a hidden staging folder inside ``folder``; on success its files
    move into ``folder`` (each move atomic; Ctrl-C and SIGTERM are held
    until the last one has moved, so an interruption gets the whole set),
    on any failure or interruption before that it is removed, so no partial
    set of outputs is left behind. ``replaces``: the files the set replaces
    as a whole, a glob (a sequence's frames) or a predicate on file names
    (an output stem's files): those in ``folder`` that the new set does not
    have are removed once it is in place, so that a shorter sequence does
    not leave an earlier one's last frames beside it, nor a match without
    pictures an earlier match's picture.
    """
    folder = ensure_output_folder(folder)
    try:
        stage = Path(tempfile.mkdtemp(dir=folder, prefix=".partial-"))
    except OSError as exc:
        raise InputError(f"{folder}: cannot write output there ({os_reason(exc)})") from None
    import shutil

    from corrlib.interrupts import signals_held

    try:
        yield stage
        entries = sorted(stage.iterdir())
        for entry in entries:  # a folder where a file goes would stop the moves half-way: none is moved
            if (folder / entry.name).is_dir():
                raise InputError(f"{folder / entry.name}: an output file goes there, but it is a folder")
        with signals_held():  # an interrupt waits until the whole set is in place and what it replaces gone
            for entry in entries:
                os.replace(entry, folder / entry.name)
            if replaces:  # what the new set replaces and does not have goes
                remove_replaced_files(folder, replaces, {entry.name for entry in entries})
    except BaseException as exc:
        shutil.rmtree(stage, ignore_errors=True)
        if isinstance(exc, OSError):
            raise InputError(f"{folder}: cannot write the outputs ({os_reason(exc)})") from None
        if isinstance(exc, CorrError) and str(stage) in str(exc):  # name the file where it was to go
            raise type(exc)(str(exc).replace(str(stage), str(folder))) from None
        raise
    shutil.rmtree(stage, ignore_errors=True)


@contextlib.contextmanager
def exclusive_folder(folder, command: str):
    """Hold the output ``folder`` for this ``command`` alone while it runs (an advisory lock on the folder,
    released when the block ends, also by a crash): two commands writing into one folder at once would mix
    their results, and each would report the other's (a benchmark's records).

    Raises
    ------
    InputError
        Naming the folder, where another process holds it. Where the file system has no locks (some network
        mounts, or a system without ``fcntl``) the folder is not guarded.
    """
    try:
        import fcntl
    except ImportError:
        yield
        return
    fd = os.open(folder, os.O_RDONLY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise InputError(f"{folder}: another {command} is writing into this folder; wait until it has "
                             "finished, or choose another output folder (-o)") from None
        except OSError:
            pass
        yield
    finally:
        os.close(fd)


def remove_replaced_files(folder: Path, replaces, kept: set[str]) -> None:
    """Remove the files of ``folder`` that ``replaces`` (a glob, or a predicate on file names) covers and whose
    names are not in ``kept``: an earlier output set's files that a new set, now in place, does not have."""
    candidates = ([entry for entry in folder.iterdir() if replaces(entry.name)] if callable(replaces)
                  else folder.glob(replaces))
    for stale in candidates:
        if stale.name not in kept and stale.is_file():
            try:
                stale.unlink()
            except OSError as exc:
                raise InputError(f"{stale}: the new outputs are written, but this file of an earlier set cannot "
                                 f"be removed ({os_reason(exc)})") from None


def lost_working_folder(path) -> str:
    """``": why"``, to append to a message that a relative ``path`` cannot be found or written, where the reason is
    that the working folder itself is gone (deleted while a shell was in it: every relative path then names
    nothing); "" otherwise."""
    if Path(path).is_absolute():
        return ""
    try:
        os.getcwd()
    except FileNotFoundError:
        return (": it is relative to the working folder, which no longer exists (deleted while in use); change "
                "to an existing folder or give an absolute path")
    return ""


def ensure_output_folder(path, what: str = "output") -> Path:
    """Create ``path`` (with parents) and check that files can be written in it, before any work.

    Raises
    ------
    InputError
        Naming the folder: it is a file, lies under a file, is not writable, or is relative to a working
        folder that no longer exists.
    """
    if str(path) == "":
        raise InputError(f"the {what} folder is an empty path")
    lost = lost_working_folder(path)
    if lost:
        raise InputError(f"{path}: cannot write {what} there{lost}")
    folder = _make_folder(Path(path), what)
    try:  # a probe file: permissions, read-only file systems
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".write-check.")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise InputError(f"{folder}: cannot write {what} there ({os_reason(exc)})") from None
    return folder


#: the output folders this process created (:func:`ensure_output_folder`), so that a command that fails can
#: remove those it left empty (:func:`remove_created_empty_folders`)
_CREATED_FOLDERS: set[Path] = set()


def remove_created_empty_folders(remove: bool = True) -> None:
    """Remove the output folders this process created that are still empty, deepest first: a command that
    stops with an error leaves no empty folder behind (its outputs are written all-or-nothing,
    :func:`staged_output`). Folders that hold anything, and folders that existed before, stay. Either way
    the record starts afresh (``remove=False``: after a command that succeeded, its folders are the user's)."""
    if remove:
        for folder in sorted(_CREATED_FOLDERS, key=lambda p: len(p.parts), reverse=True):
            with contextlib.suppress(OSError):  # not empty, or gone
                folder.rmdir()
    _CREATED_FOLDERS.clear()


def _make_folder(folder: Path, what: str) -> Path:
    """``mkdir -p`` with an :class:`InputError` naming the folder and, if so, the file in its way."""
    try:
        missing = [p for p in (folder, *folder.parents) if not p.exists()]
        folder.mkdir(parents=True, exist_ok=True)
        _CREATED_FOLDERS.update(p.absolute() for p in missing)
    except OSError as exc:
        blocking = next((p for p in [folder, *folder.parents] if p.exists() and not p.is_dir()), None)
        dangling = next((p for p in [folder, *folder.parents] if p.is_symlink() and not p.exists()), None)
        if blocking == folder:
            reason = "it is a file"
        elif blocking is not None:
            reason = f"{blocking} is a file, not a folder"
        elif dangling is not None:
            reason = f"{dangling} is a symbolic link to {os.readlink(dangling)}, which does not exist"
        else:
            reason = os_reason(exc)
        raise InputError(f"{folder}: cannot write {what} there ({reason})") from None
    return folder
