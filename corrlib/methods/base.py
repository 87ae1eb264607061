"""What every correspondence method shares: parameter fields, the result type, validation.

A method's parameters are a frozen, keyword-only dataclass whose fields are
made with :func:`param`; the field metadata (label, bounds, choices, help)
lets the CLI and the studio build their forms and validate values before a
run. A method's result is a :class:`MatchResult`.

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

from corrlib.errors import ParameterError


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
            if value not in meta["choices"]:
                raise ParameterError(f"{f.name} = {value!r} is not one of {', '.join(map(str, meta['choices']))}")
            continue
        if isinstance(f.default, bool):
            if not isinstance(value, (bool, np.bool_)):
                raise ParameterError(f"{f.name} must be true or false, got {value!r}")
            continue
        if isinstance(f.default, (int, float)) and f.default is not None:
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise ParameterError(f"{f.name} must be a number, got {value!r}")
            if not math.isfinite(float(value)):
                raise ParameterError(f"{f.name} must be finite, got {value!r}")
            if meta.get("integer") and float(value) != int(value):
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
class MatchResult:
    """The outcome of a correspondence method.

    Attributes
    ----------
    method : str
        Registry name of the method.
    map_xy : (n_x,) int or None
        Target vertex for every source vertex (-1 where unmatched).
    map_yx : (n_y,) int or None
        Source vertex for every target vertex (-1 where unmatched).
    energy : float or None
        The method's objective at the solution (lower is better unless the
        method says otherwise in ``extras["energy_sense"]``).
    timings : dict of str -> float
        Seconds per stage.
    params : dict
        The parameters used.
    extras : dict
        Method-specific arrays and values (contour path, deformation, energy trace...).
    """

    method: str
    map_xy: np.ndarray | None = None
    map_yx: np.ndarray | None = None
    energy: float | None = None
    timings: dict[str, float] = field(default_factory=dict)
    params: dict[str, Any] = field(default_factory=dict)
    extras: dict[str, Any] = field(default_factory=dict)

    def save(self, stem) -> tuple[Path, Path]:
        """Write ``stem.npz`` (maps and array extras) and ``stem.json`` (everything else)."""
        from corrlib.io import save_result

        arrays = {}
        meta: dict[str, Any] = {"method": self.method, "energy": self.energy, "timings": self.timings,
                                "params": self.params}
        if self.map_xy is not None:
            arrays["map_xy"] = self.map_xy
        if self.map_yx is not None:
            arrays["map_yx"] = self.map_yx
        scalars = {}
        for key, value in self.extras.items():
            if isinstance(value, np.ndarray) and value.dtype != object:
                arrays[key] = value
            else:
                scalars[key] = value
        meta["extras"] = scalars
        return save_result(stem, arrays, meta)
