"""The one registry of correspondence methods, used by the CLI, the studio and the benchmarks.

A method registers a :class:`MethodSpec`: its name, the input kinds it
accepts, its parameter dataclass and its solver generator, a :class:`Solver`

``solve_<name>(source, target, params, token) -> Generator[Progress, None, MatchResult]``

(a :class:`RefiningSolver` also takes a keyword-only ``initial=``).

:func:`solve` runs one to completion; the studio iterates the generator in a
worker thread. The registry does not import the methods: the package
``corrlib.methods`` does (its ``__init__`` runs before any of its modules,
this one included, is imported), so the registry is complete whenever it is
reachable.
"""

from __future__ import annotations

import time
from collections.abc import Generator
from dataclasses import asdict, dataclass
from typing import Any, Protocol


from corrlib.errors import InputError, ParameterError
from corrlib.methods.base import InitialMatch, MatchResult, documented_params, make_params, validate_params
from corrlib.progress import CancelToken, Progress, run
from corrlib.shapes import Contour2D, TriMesh



class Solver(Protocol):
    """A method's solver: a generator of progress reports that returns the result.

    ``token`` is always given (the registry makes one); the solver checks it
    between stages and raises :class:`~corrlib.errors.Cancelled` through it.
    """

    def __call__(self, source: Any, target: Any, params: Any, token: CancelToken
                 ) -> Generator[Progress, None, MatchResult]: ...


class RefiningSolver(Protocol):
    """A solver that can also start from another map or landmarks (``MethodSpec.refines``)."""

    def __call__(self, source: Any, target: Any, params: Any, token: CancelToken, *, initial: Any = None
                 ) -> Generator[Progress, None, MatchResult]: ...


SolveFn = Solver | RefiningSolver


@dataclass(frozen=True)
class MethodSpec:
    """A registered method.

    Attributes
    ----------
    name : str
        Registry key, e.g. ``"kernel-matching"``.
    label : str
        Human name.
    inputs : tuple of str
        Kinds of (source, target): ``"mesh"`` or ``"contour"``.
    params : type
        Frozen parameter dataclass.
    solve : callable
        The solver generator.
    description : str
        One paragraph for help texts.
    rank : int
        Preference when "the best available method" is asked for (higher first).
    """

    name: str
    label: str
    inputs: tuple[str, str]
    params: type
    solve: SolveFn
    description: str = ""
    rank: int = 0
    #: the solver accepts ``initial=`` (a starting map or landmarks) and can refine another method's map
    refines: bool = False
    #: the result carries a deformation model (a flow, ``MatchResult.deformation``) that sequences follow
    deforms: bool = False

    def __repr__(self) -> str:
        return f"MethodSpec({self.name!r}, {self.inputs[0]} -> {self.inputs[1]}, params={self.params.__name__})"


_REGISTRY: dict[str, MethodSpec] = {}


def register(spec: MethodSpec) -> MethodSpec:
    """Add a method to the registry (a name can be registered once)."""
    if spec.name in _REGISTRY and _REGISTRY[spec.name] is not spec:
        raise ParameterError(f"method {spec.name!r} is already registered")
    documented_params(spec.params)
    _REGISTRY[spec.name] = spec
    return spec


def all_methods() -> list[MethodSpec]:
    """Every registered method, best-ranked first."""
    return sorted(_REGISTRY.values(), key=lambda s: (-s.rank, s.name))


def get_method(name: str) -> MethodSpec:
    """The method called ``name``; :class:`ParameterError` lists the known names otherwise."""
    if not isinstance(name, str) or name not in _REGISTRY:
        raise ParameterError(f"unknown method {name!r} (available: {', '.join(sorted(_REGISTRY))})")
    return _REGISTRY[name]


def kind_of(shape) -> str:
    """``"mesh"`` or ``"contour"``."""
    if isinstance(shape, TriMesh):
        return "mesh"
    if isinstance(shape, Contour2D):
        return "contour"
    raise InputError(f"unsupported input type {type(shape).__name__} (expected TriMesh or Contour2D)")


def methods_for(source, target) -> list[MethodSpec]:
    """Registered methods accepting this pair of inputs, best-ranked first."""
    kinds = (kind_of(source), kind_of(target))
    return [s for s in all_methods() if s.inputs == kinds]


def input_record(shape) -> dict:
    """What :attr:`MatchResult.inputs` keeps of a matched shape: its name, kind, size and (a mesh) content
    hash and shape print, so that a saved result says which shapes it maps (``evaluate`` refuses a target of
    another size or, by the print, another shape of the same size)."""
    if kind_of(shape) == "mesh":
        return {"name": shape.name, "kind": "mesh", "vertices": int(shape.n_vertices),
                "faces": int(shape.faces.shape[0]), "content_hash": shape.content_hash,
                "shape_print": [float(d) for d in shape.shape_print]}
    return {"name": shape.name, "kind": "contour", "points": int(shape.n_points)}


def check_inputs(spec: MethodSpec, source, target) -> None:
    """:class:`InputError` unless the method takes this pair of inputs (a mesh or a contour on each side)."""
    kinds = (kind_of(source), kind_of(target))
    if kinds != spec.inputs:
        raise InputError(f"method {spec.name!r} takes {spec.inputs[0]} + {spec.inputs[1]}, "
                         f"got {kinds[0]} + {kinds[1]}")


def solve_iter(method: str | MethodSpec, source, target, params=None, token: CancelToken | None = None, *,
               initial=None, **overrides):
    """Generator form of :func:`solve` (what the studio runs in a worker thread).

    Validates the inputs and parameters, yields the method's progress and
    returns its :class:`MatchResult` with ``timings["total"]``, ``params``
    and ``method`` filled in.
    """
    spec = method if isinstance(method, MethodSpec) else get_method(method)
    check_inputs(spec, source, target)
    if params is None:
        params = make_params(spec.params, **overrides)
    elif not isinstance(params, spec.params):
        raise ParameterError(f"params of {spec.name!r} must be a {spec.params.__name__} (make_params or keyword "
                             f"overrides), got {type(params).__name__}")
    elif overrides:  # they would be dropped without a word
        raise ParameterError(f"give params or keyword overrides, not both (got params and {', '.join(overrides)})")
    else:
        validate_params(params)
    token = token or CancelToken()
    if initial is not None and not spec.refines:
        raise InputError(f"method {spec.name!r} does not take an initial map")
    if initial is not None and not isinstance(initial, InitialMatch):  # a dense map given as an array
        initial = InitialMatch(map_xy=initial)
    if initial is not None and kind_of(source) == kind_of(target) == "mesh":
        initial.pairs(source.n_vertices, target.n_vertices)  # checked before any work
    start = time.perf_counter()
    gen = spec.solve(source, target, params, token, initial=initial) if spec.refines else \
        spec.solve(source, target, params, token)
    result = yield from gen
    result.timings.setdefault("total", time.perf_counter() - start)
    result.params = asdict(params)
    result.method = spec.name
    result.inputs = {"source": input_record(source), "target": input_record(target)}
    return result


def solve(method: str | MethodSpec, source, target, params=None, *, callback=None,
          token: CancelToken | None = None, initial=None, **overrides) -> MatchResult:
    """Run a registered method to completion.

    Parameters
    ----------
    method : str or MethodSpec
    source, target : TriMesh or Contour2D
    params : parameter dataclass instance, optional
        The method's parameters (``make_params(spec.params, name=value)``; ``help(spec.params)`` lists them and
        what they mean). Without it, the method's defaults changed by the keyword ``overrides``
        (``solve("kernel-matching", x, y, n_eigs=300)``); giving both is refused, so that no value is dropped.
    callback : callable, optional
        Receives every :class:`Progress`.
    token : CancelToken, optional
    initial : InitialMatch or (n_source,) int array, optional
        Starting point for methods that refine a map (``spec.refines``): an
        :class:`corrlib.methods.base.InitialMatch`, or a dense map (-1: no
        partner), which is wrapped in one.

    Returns
    -------
    MatchResult
        With ``timings["total"]`` and ``params`` filled in.
    """
    if callback is not None and not callable(callback):
        raise ParameterError(f"callback must be a function that takes a Progress report, got "
                             f"{type(callback).__name__} {callback!r:.40}")
    if token is not None and not isinstance(token, CancelToken):
        raise ParameterError(f"token must be a corrlib.progress.CancelToken, got {type(token).__name__}")
    token = token or CancelToken()
    return run(solve_iter(method, source, target, params, token, initial=initial, **overrides),
               callback=callback, token=token)
