"""Exception hierarchy of corrlib.

Every error that bad input can cause is a :class:`CorrError` whose message
names the offending file or argument and the problem, so the CLI can print it
and exit with status 2 and the studio can show it in a dialog.

``InputError`` and ``ParameterError`` also derive from :class:`ValueError`,
so callers that only know the standard library still catch them.
"""

from __future__ import annotations


class CorrError(Exception):
    """Base class of every error raised on purpose by corrlib."""


class InputError(CorrError, ValueError):
    """Input data (arrays or files) that cannot be used."""


class FileFormatError(InputError):
    """A file that cannot be read or parsed, or has an unsupported format."""


class MeshError(InputError):
    """A triangle mesh that fails validation (degenerate, non-manifold, ...)."""


class ContourError(InputError):
    """A 2D contour that fails validation (open, self-intersecting, too short, ...)."""


class ParameterError(CorrError, ValueError):
    """A parameter value outside its documented range."""


class SolverError(CorrError, RuntimeError):
    """A numerical solver failed on input that passed validation."""


class Cancelled(CorrError):
    """The computation was cancelled through its :class:`~corrlib.progress.CancelToken`."""
