"""What every correspondence method shares: parameter fields, the result type, validation.

A method's parameters are a frozen, keyword-only dataclass whose fields are
made with :func:`param`; the field metadata (label, bounds, choices, help)
lets the CLI and the studio build their forms and validate values before a
run. A method's result is a :class:`MatchResult`, whose method-specific parts are
typed: a :class:`ContourPath` and a :class:`SearchCertificate` for the contour
methods, a deformation for the divergence-free flow.

Map convention: ``map_xy[i]`` is the vertex of the target Y matched to
vertex ``i`` of the source X; ``map_yx[j]`` the vertex of X matched to
vertex ``j`` of Y. Colour transfer onto Y uses ``map_yx``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from corrlib.errors import InputError, ParameterError
from corrlib.io import checked_map, vertex_indices


def param(default, *, label: str, help: str, low: float | None = None, high: float | None = None,
          choices: tuple | None = None, integer: bool | None = None):
    """A parameter field with GUI/CLI metadata.

    Parameters
    ----------
    default
        Default value (the paper's choice where it has one).
    label : str
        Short human label.
    help : str
        What the parameter means, in the paper's terms.
    low, high : float, optional
        Inclusive bounds for numbers.
    choices : tuple, optional
        Allowed values for strings.
    integer : bool, optional
        Whether the value must be an integer (default: inferred from ``default``).
    """
    if integer is None:
        integer = isinstance(default, int) and not isinstance(default, bool)
    meta = {"label": label, "help": help, "low": low, "high": high, "choices": choices, "integer": integer}
    return field(default=default, metadata=meta)


def param_fields(params_cls) -> list[dataclasses.Field]:
    """The fields of a parameter dataclass, in declaration order."""
    return list(dataclasses.fields(params_cls))


def parameter_line(f: dataclasses.Field) -> str:
    """``name=default [low, high]: help`` (or ``choices (…)``) of one parameter field, as ``corr methods`` and
    the parameter classes' docstrings list it."""
    m = f.metadata
    allowed = f" choices {m['choices']}" if m.get("choices") else (
        f" [{m.get('low')}, {m.get('high')}]" if m.get("low") is not None else "")
    return f"{f.name}={f.default}{allowed}: {m.get('help', '')}"


#: where :func:`documented_params` starts the list it appends to a parameter class's docstring
PARAMETERS_HEADING = "Parameters (name=default [range]: meaning)"


def documented_params(params_cls) -> type:
    """``params_cls`` with the meaning of every field appended to its docstring (once), so that ``help()`` on a
    method's parameters shows what the studio's tooltips and ``corr methods`` show."""
    doc = params_cls.__doc__ or ""
    if PARAMETERS_HEADING not in doc:
        lines = [f"    {parameter_line(f)}" for f in param_fields(params_cls)]
        params_cls.__doc__ = f"{doc.rstrip()}\n\n{PARAMETERS_HEADING}\n\n" + "\n".join(lines) + "\n"
    return params_cls


def validate_params(params) -> None:
    """Check every field of a parameter dataclass instance against its metadata.

    Raises
    ------
    ParameterError
        Naming the field, its value and the allowed range or choices.
    """
    for f in dataclasses.fields(params):
        value = getattr(params, f.name)
        meta = f.metadata
        if meta.get("choices") is not None:
            if not isinstance(value, (str, bool, int, float)) or value not in meta["choices"]:
                raise ParameterError(f"{f.name} = {value!r} is not one of {', '.join(map(str, meta['choices']))}")
            continue
        if isinstance(f.default, bool):
            if not isinstance(value, (bool, np.bool_)):
                raise ParameterError(f"{f.name} must be true or false, got {value!r}")
            continue
        if isinstance(f.default, str) and not isinstance(value, str):
            raise ParameterError(f"{f.name} must be text, got {value!r}")
        if isinstance(f.default, (int, float)) and f.default is not None:
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise ParameterError(f"{f.name} must be a number, got {value!r}")
            try:
                finite = math.isfinite(float(value))
            except OverflowError:  # an integer beyond every float
                raise ParameterError(f"{f.name} must be finite, got an integer of {len(str(value))} digits") from None
            if not finite:
                raise ParameterError(f"{f.name} must be finite, got {value!r}")
            if isinstance(f.default, int) and not isinstance(value, (int, np.integer)):
                raise ParameterError(f"{f.name} must be an integer, got {value!r}")
            if meta.get("integer") and not isinstance(value, (int, np.integer)) and float(value) != int(value):
                raise ParameterError(f"{f.name} must be an integer, got {value!r}")
            low, high = meta.get("low"), meta.get("high")
            if low is not None and value < low:
                raise ParameterError(f"{f.name} = {value!r} is below its minimum {low}")
            if high is not None and value > high:
                raise ParameterError(f"{f.name} = {value!r} is above its maximum {high}")


def make_params(params_cls, **overrides):
    """Instantiate a parameter dataclass with overrides (strings are converted) and validate it."""
    names = {f.name: f for f in dataclasses.fields(params_cls)}
    kwargs = {}
    for key, value in overrides.items():
        key = key.replace("-", "_")
        if key not in names:
            raise ParameterError(f"unknown parameter {key!r} (known: {', '.join(names)})")
        kwargs[key] = _convert(names[key], value)
    params = params_cls(**kwargs)
    validate_params(params)
    return params


def _convert(f: dataclasses.Field, value):
    if not isinstance(value, str):
        return value
    default = f.default
    try:
        if isinstance(default, bool):
            if value.lower() in {"1", "true", "yes", "on"}:
                return True
            if value.lower() in {"0", "false", "no", "off"}:
                return False
            raise ValueError(value)
        if isinstance(default, int):
            return int(value)
        if isinstance(default, float):
            return float(value)
    except ValueError:
        raise ParameterError(f"{f.name}: cannot interpret {value!r} as {type(default).__name__}") from None
    return value


@dataclass
class InitialMatch:
    """A starting point for a refining method (``MethodSpec.refines``): another method's output or landmarks.

    Either a dense map (``map_xy``, -1 allowed) or sparse landmarks
    (``landmarks_x``, ``landmarks_y``). Landmarks are kept as anchors in every
    score, so they stay matched (kernel matching does not reassign them; its
    final ZoomOut step, if on, moves every vertex to its nearest partner in
    the basis).
    """

    map_xy: np.ndarray | None = None
    landmarks_x: np.ndarray | None = None
    landmarks_y: np.ndarray | None = None

    def __post_init__(self):
        given = (self.map_xy is not None, self.landmarks_x is not None or self.landmarks_y is not None)
        if given == (True, True):
            raise InputError("an initial match is a map or landmarks, not both")
        if given == (False, False):
            raise InputError("an initial match needs a map (map_xy) or landmarks (landmarks_x and landmarks_y)")
        if given[1] and (self.landmarks_x is None or self.landmarks_y is None):
            raise InputError("landmarks need both landmarks_x (source vertices) and landmarks_y (target vertices)")

    def pairs(self, n_x: int, n_y: int) -> tuple[np.ndarray, np.ndarray]:
        """The matched ``(source, target)`` vertex pairs, checked against the vertex counts: integer indices in
        range (-1 in a map: no partner), one target per source vertex."""
        if self.map_xy is not None:
            mp = checked_map(self.map_xy, n_x, n_y, "the initial map")
            keep = np.flatnonzero(mp >= 0)
            return keep, mp[keep]
        lx, ly = vertex_indices(self.landmarks_x, "landmarks_x"), vertex_indices(self.landmarks_y, "landmarks_y")
        if lx.ndim != 1 or lx.size == 0 or lx.shape != ly.shape:
            raise InputError(f"landmarks need two equally long 1-D lists of source and target indices, got shapes "
                             f"{lx.shape} and {ly.shape}")
        for side, indices, n in (("source", lx, n_x), ("target", ly, n_y)):
            bad = np.flatnonzero((indices < 0) | (indices >= n))
            if bad.size:
                raise InputError(f"landmark {bad[0]}: {side} vertex {indices[bad[0]]} is out of range for a "
                                 f"{n}-vertex {side} (0 to {n - 1})")
        _, first = np.unique(np.column_stack([lx, ly]), axis=0, return_index=True)
        pairs = np.column_stack([lx, ly])[np.sort(first)]  # a pair given twice counts once; the order is kept
        sources, counts = np.unique(pairs[:, 0], return_counts=True)
        if np.any(counts > 1):
            twice = sources[np.argmax(counts > 1)]
            raise InputError(f"landmarks send source vertex {twice} to several targets "
                             f"({', '.join(map(str, pairs[pairs[:, 0] == twice, 1]))}); give one")
        return pairs[:, 0], pairs[:, 1]


def same_values(a, b) -> bool:
    """Whether two values of a result hold the same data: arrays by shape and entries (NaN equal to NaN, as a
    saved and reloaded result has them), mappings key by key, lists and tuples item by item (JSON gives tuples
    back as lists), dataclasses field by field, anything else by ``==``. A result's fields are arrays, so the
    dataclasses' generated ``==`` (which asks an array for one truth value) cannot compare them."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        if a.shape != b.shape:
            return False
        numeric = a.dtype.kind in "fc" and b.dtype.kind in "fc"
        return bool(np.array_equal(a, b, equal_nan=numeric)) if a.dtype != object else all(
            same_values(x, y) for x, y in zip(a.ravel(), b.ravel()))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same_values(a[key], b[key]) for key in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(same_values(x, y) for x, y in zip(a, b))
    if dataclasses.is_dataclass(a) and not isinstance(a, type):
        return type(a) is type(b) and all(same_values(getattr(a, f.name), getattr(b, f.name))
                                          for f in dataclasses.fields(a))
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return bool(a == b)


@dataclass(frozen=True, eq=False)
class ContourPath:
    """A closed path on the product graph of a contour and a shape (thesis §7.3, Eq. 7.6).

    Step ``s`` of the path pairs contour point ``contour_index[s]`` with
    vertex ``vertices[s]`` of the target (a mesh vertex, or a point of the
    target contour for 2D-to-2D matching).

    Attributes
    ----------
    contour_points : (m, 2) float
        The query contour as it was matched.
    vertices : (k,) int
        Target vertex (or target contour point) at every step.
    contour_index : (k,) int
        Contour point at every step (in ``0 .. m-1``).
    layers : (k,) int
        Product-graph layer at every step (the unrolled contour position).
    target_points : (n, 2) float or None
        The target contour, when the target is a contour.
    product_functions : dict of str -> (m, n) float
        Functions on the product of two contours (the torus) that the path
        was found on or refined with, e.g. ``"cost"``; empty for a mesh target.
    """

    contour_points: np.ndarray
    vertices: np.ndarray
    contour_index: np.ndarray
    layers: np.ndarray
    target_points: np.ndarray | None = None
    product_functions: dict[str, np.ndarray] = field(default_factory=dict)

    def __eq__(self, other) -> bool:
        return same_values(self, other) if isinstance(other, ContourPath) else NotImplemented

    __hash__ = None  # holds arrays: compared by value, not hashed


@dataclass(frozen=True)
class SearchCertificate:
    """What a branch-and-bound search proves about its path (thesis §7.4).

    Attributes
    ----------
    lower_bound, upper_bound : float
        Bounds on the optimal energy; the returned path attains ``upper_bound``.
    iterations : int
        Branch-and-bound iterations.
    dijkstra_runs : int
        Layered shortest-path computations.
    seconds_per_dijkstra : float
    eps : float
        The approximation asked for: the search stops once ``lower_bound · (1 + eps) ≥ upper_bound``, or at its
        iteration cap before that.
    """

    lower_bound: float
    upper_bound: float
    iterations: int
    dijkstra_runs: int = 0
    seconds_per_dijkstra: float = 0.0
    eps: float = 0.0

    @classmethod
    def of(cls, search, eps: float = 0.0) -> "SearchCertificate":
        """The certificate of a :class:`~corrlib.geometry.cyclic_paths.BranchAndBoundResult` searched with
        approximation ``eps``."""
        return cls(float(search.lower_bound), float(search.upper_bound), int(search.iterations),
                   int(search.dijkstra_runs), float(search.seconds_per_run), float(eps))

    @property
    def optimal(self) -> bool:
        """Whether the path is proven globally optimal (not only within the ε bound)."""
        return bool(self.lower_bound >= self.upper_bound)

    @property
    def within_bound(self) -> bool:
        """Whether the path is proven within the asked factor ``1 + eps`` of the optimum (False: the search
        stopped at its iteration cap first)."""
        return bool(self.lower_bound * (1.0 + self.eps) >= self.upper_bound)

    def describe(self) -> str:
        """What the search proves, in words: optimal, within the ε bound, or neither (stopped at the cap)."""
        if self.optimal:
            return "proven optimal"
        if self.within_bound:
            return f"within the ε = {self.eps:g} bound of the optimum"
        return (f"NOT proven optimal: the search stopped at its iteration cap ({self.iterations} iterations) "
                f"with the optimum between {self.lower_bound:.6g} and {self.upper_bound:.6g} "
                f"({100 * self.gap / max(abs(self.upper_bound), 1e-300):.2g} % of the energy)")

    @property
    def gap(self) -> float:
        """``upper_bound - lower_bound`` (0 at a proven optimum)."""
        return float(max(self.upper_bound - self.lower_bound, 0.0))


#: array names under which :meth:`MatchResult.save` stores the typed fields
_PATH_ARRAYS = {"contour_points": "contour_points", "vertices": "path_vertices",
                "contour_index": "path_contour_index", "layers": "path_layers", "target_points": "target_points"}
_DEFORMATION_ARRAYS = ("coefficients", "frames", "trajectory_times", "trajectory")


@dataclass(eq=False)
class MatchResult:
    """The outcome of a correspondence method.

    Attributes
    ----------
    method : str
        Registry name of the method.
    map_xy : (n_x,) int or None
        Target vertex for every source vertex (-1 where unmatched). For a contour source, one per point of the
        contour as resampled for the match (``path.contour_points``), not per point of the drawing.
    map_yx : (n_y,) int or None
        Source vertex for every target vertex (-1 where unmatched).
    energy : float or None
        The method's objective at the solution.
    timings : dict of str -> float
        Seconds per stage, and ``"total"`` (the wall time of the whole solve). Stages that ran side by side
        (kernel matching's ``"other start"``) overlap the rest, so the stages can add up to more than the
        total: compare methods by ``"total"``.
    params : dict
        The parameters used.
    energy_sense : {"min", "max"}
        Whether the method minimises or maximises ``energy``.
    energy_meaning : str
        What ``energy`` measures, in the method's terms.
    energy_trace : (i,) float or None
        The objective after every iteration, for iterative methods.
    path : ContourPath or None
        The matched closed curve of a contour method.
    search : SearchCertificate or None
        Bounds of a branch-and-bound search.
    deformation : corrlib.deformation.model.Deformation or None
        The fitted flow of a deformation method.
    extras : dict
        Method-specific diagnostics (iteration counts, traces, intermediate
        arrays) for printing and inspection; no code path depends on them.
    inputs : dict
        What was matched (``solve`` fills it in, :meth:`save` keeps it): ``{"source": ..., "target": ...}``,
        each the shape's ``name``, ``kind`` ("mesh" or "contour"), its ``vertices`` and ``faces`` or its
        ``points``, and a mesh's ``content_hash`` and ``shape_print``; empty for a result made by hand.
    """

    method: str
    map_xy: np.ndarray | None = None
    map_yx: np.ndarray | None = None
    energy: float | None = None
    timings: dict[str, float] = field(default_factory=dict)
    params: dict[str, Any] = field(default_factory=dict)
    energy_sense: str = "min"
    energy_meaning: str = ""
    energy_trace: np.ndarray | None = None
    path: ContourPath | None = None
    search: SearchCertificate | None = None
    deformation: Any = None
    extras: dict[str, Any] = field(default_factory=dict)
    inputs: dict[str, dict] = field(default_factory=dict)

    def __eq__(self, other) -> bool:
        """Equal results hold the same values in every field (:func:`same_values`; a deformation by the arrays
        and steps :meth:`save` stores), so that a result reloaded by :meth:`load` equals the one saved."""
        if not isinstance(other, MatchResult):
            return NotImplemented
        plain = [f.name for f in dataclasses.fields(self) if f.name != "deformation"]
        if not all(same_values(getattr(self, name), getattr(other, name)) for name in plain):
            return False
        if (self.deformation is None) != (other.deformation is None):
            return False
        return self.deformation is None or (
            self.deformation.n_steps == other.deformation.n_steps
            and same_values(_deformation_arrays(self.deformation), _deformation_arrays(other.deformation)))

    __hash__ = None  # mutable and holds arrays

    def save(self, stem) -> tuple[Path, Path]:
        """Write ``stem.npz`` (maps, typed arrays and array extras) and ``stem.json`` (everything else).

        :meth:`load` reads both back into an equal result.
        """
        from corrlib.io import save_result

        arrays: dict[str, np.ndarray] = {}
        meta: dict[str, Any] = {"method": self.method, "energy": self.energy, "timings": self.timings,
                                "params": self.params, "energy_sense": self.energy_sense,
                                "energy_meaning": self.energy_meaning, "inputs": self.inputs}
        for name in ("map_xy", "map_yx", "energy_trace"):
            if getattr(self, name) is not None:
                arrays[name] = getattr(self, name)
        if self.path is not None:
            for attr, key in _PATH_ARRAYS.items():
                if getattr(self.path, attr) is not None:
                    arrays[key] = getattr(self.path, attr)
            arrays.update({f"product.{name}": f for name, f in self.path.product_functions.items()})
        if self.search is not None:
            meta["search"] = dataclasses.asdict(self.search)
        if self.deformation is not None:
            arrays.update(_deformation_arrays(self.deformation))
            meta["deformation_steps"] = self.deformation.n_steps
        scalars = {}
        for key, value in self.extras.items():
            if isinstance(value, np.ndarray) and value.dtype != object:
                arrays[f"extras.{key}"] = value
            else:
                scalars[key] = value
        meta["extras"] = scalars
        return save_result(stem, arrays, meta)

    @classmethod
    def load(cls, stem) -> "MatchResult":
        """Read a result written by :meth:`save` (``stem``, ``stem.npz`` or ``stem.json``);
        :class:`~corrlib.errors.FileFormatError` for files that are not one."""
        from corrlib.errors import FileFormatError
        from corrlib.io import load_result

        arrays, meta = load_result(stem)
        try:
            return cls._from_saved(arrays, meta)
        except (TypeError, ValueError, KeyError, AttributeError) as exc:  # another program's files, or edited ones
            raise FileFormatError(f"{stem}: not a result written by corrlib ({type(exc).__name__}: {exc})") from None

    @classmethod
    def _from_saved(cls, arrays: dict, meta: dict) -> "MatchResult":
        result = cls(str(meta.get("method", "")), arrays.get("map_xy"), arrays.get("map_yx"), meta.get("energy"),
                     dict(meta.get("timings", {})), dict(meta.get("params", {})),
                     str(meta.get("energy_sense", "min")), str(meta.get("energy_meaning", "")),
                     arrays.get("energy_trace"))
        if "path_vertices" in arrays:
            functions = {k.split(".", 1)[1]: v for k, v in arrays.items() if k.startswith("product.")}
            result.path = ContourPath(**{attr: arrays.get(key) for attr, key in _PATH_ARRAYS.items()},
                                      product_functions=functions)
        if meta.get("search"):
            result.search = SearchCertificate(**meta["search"])
        if "coefficients" in arrays and "frames" in arrays:
            from corrlib.deformation.model import Deformation

            result.deformation = Deformation.from_arrays(
                arrays["coefficients"], arrays["frames"], int(meta.get("deformation_steps", 20)),
                arrays.get("trajectory_times"), arrays.get("trajectory"))
        result.inputs = dict(meta.get("inputs", {}))
        result.extras = dict(meta.get("extras", {}))
        result.extras.update({k.split(".", 1)[1]: v for k, v in arrays.items() if k.startswith("extras.")})
        return result


def _deformation_arrays(deformation) -> dict[str, np.ndarray]:
    """The arrays that rebuild a :class:`~corrlib.deformation.model.Deformation` (with its stored steps)."""
    out = {"coefficients": deformation.coeffs, "frames": deformation.frames.as_array()}
    if deformation.source_steps is not None:
        out["trajectory_times"] = deformation.source_steps.times
        out["trajectory"] = deformation.source_steps.positions
    return out
