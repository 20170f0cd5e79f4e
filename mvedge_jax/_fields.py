"""One idiom for the fields of every stage config (frozen ``eqx.Module``s).

Two kinds of field:

* `hyperparameter`: a real scalar stored as a 0-d floating JAX array (a pytree leaf). Changing
  its value never recompiles, and it can be swept with ``vmap`` or differentiated. Its
  metadata says whether the chain is differentiable with respect to it
  (``differentiable=True``) or whether it is a threshold, i.e. piecewise constant
  (``differentiable=False``; the gradient with respect to it is zero wherever it exists).
* `static`: an option that changes array shapes or control flow (counts, capacities, flags,
  names of strategies). Changing it recompiles.

Every config calls `check_fields` from its ``__check_init__``: concrete values are validated
against the field's declared type, choices and bounds, and every error names the config and
the field. Traced values (a config built inside ``jit``/``vmap``) are not checked.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

_META = "mvedge"


@dataclasses.dataclass(frozen=True)
class FieldSpec:
    """What a config field accepts.

    Attributes:
        kind: ``"hyperparameter"``, ``"vector"`` (a 1-D float array leaf of ``length``),
            ``"int"``, ``"float"``, ``"bool"`` or ``"str"``.
        differentiable: for hyperparameters, whether the chain's output is a smooth function
            of the field (where its other, discrete decisions do not change).
        lower, upper: inclusive bounds (``None``: unbounded).
        lower_open: the lower bound itself is excluded (``> lower``).
        choices: allowed values of a ``"str"`` field.
        optional: ``None`` is allowed.
    """

    kind: str
    differentiable: bool = False
    length: int | None = None
    lower: float | None = None
    upper: float | None = None
    lower_open: bool = False
    choices: tuple | None = None
    optional: bool = False


def as_float(value: Any) -> Any:
    """Converter of `hyperparameter` fields: a real scalar becomes a weakly typed 0-d float
    array (float32, or float64 under ``jax_enable_x64``; weak typing lets it follow the
    precision of the arrays it meets). Anything else is returned unchanged for `check_fields`
    to reject with the field's name; tracers pass through."""
    if isinstance(value, jax.core.Tracer):
        return value
    if isinstance(value, bool | np.bool_ | str | bytes) or value is None:
        return value
    arr = np.asarray(value)
    if arr.ndim != 0 or not np.issubdtype(arr.dtype, np.number):
        return value
    if np.issubdtype(arr.dtype, np.complexfloating):
        return value
    return jnp.asarray(float(arr))


def hyperparameter(
    default: float,
    *,
    differentiable: bool,
    lower: float | None = None,
    upper: float | None = None,
    lower_open: bool = False,
):
    """A real scalar config field stored as an array leaf (see the module docstring)."""
    spec = FieldSpec(
        "hyperparameter",
        differentiable=differentiable,
        lower=lower,
        upper=upper,
        lower_open=lower_open,
    )
    return eqx.field(default=default, converter=as_float, metadata={_META: spec})


def as_float_vector(value: Any) -> Any:
    """Converter of `hyperparameter_vector` fields: a sequence of real numbers becomes a 1-D
    float array (see `as_float`); anything else is returned unchanged for `check_fields`."""
    if isinstance(value, jax.core.Tracer | str | bytes) or value is None:
        return value
    arr = np.asarray(value)
    if arr.ndim != 1 or not np.issubdtype(arr.dtype, np.number) or arr.dtype == bool:
        return value
    if np.issubdtype(arr.dtype, np.complexfloating):
        return value
    return jnp.asarray(arr.astype(float), dtype=jnp.result_type(float))


def hyperparameter_vector(
    default: tuple[float, ...],
    *,
    differentiable: bool,
    lower: float | None = None,
    upper: float | None = None,
):
    """A fixed-length vector of real hyperparameters stored as a 1-D array leaf."""
    spec = FieldSpec(
        "vector", differentiable=differentiable, length=len(default), lower=lower, upper=upper
    )
    return eqx.field(default=default, converter=as_float_vector, metadata={_META: spec})


def static(
    default: Any,
    *,
    kind: str | None = None,
    lower: float | None = None,
    upper: float | None = None,
    lower_open: bool = False,
    choices: tuple | None = None,
    optional: bool = False,
):
    """A static config field (changing it recompiles); ``kind`` defaults to the type of
    ``default``."""
    if kind is None:
        kind = {bool: "bool", int: "int", float: "float", str: "str"}[type(default)]
    spec = FieldSpec(
        kind,
        lower=lower,
        upper=upper,
        lower_open=lower_open,
        choices=choices,
        optional=optional or default is None,
    )
    return eqx.field(static=True, default=default, metadata={_META: spec})


def field_spec(field: dataclasses.Field) -> FieldSpec | None:
    """The `FieldSpec` of a dataclass field, or ``None`` for a field declared otherwise."""
    return field.metadata.get(_META)


def _bounds_text(spec: FieldSpec) -> str:
    parts = []
    if spec.lower is not None:
        parts.append(f"{'>' if spec.lower_open else '>='} {spec.lower:g}")
    if spec.upper is not None:
        parts.append(f"<= {spec.upper:g}")
    return " and ".join(parts)


def _check_bounds(where: str, value: float, spec: FieldSpec) -> None:
    low_ok = spec.lower is None or (value > spec.lower if spec.lower_open else value >= spec.lower)
    high_ok = spec.upper is None or value <= spec.upper
    if not (low_ok and high_ok):
        raise ValueError(f"{where} must be {_bounds_text(spec)}; got {value!r}")


def check_value(where: str, value: Any, spec: FieldSpec) -> None:
    """Validate one concrete field value against its spec.

    Raises:
        TypeError: a value of the wrong type (a string or bool for a number, an array for a
            scalar, a float for an integer).
        ValueError: a value outside its bounds or choices, or a non-finite hyperparameter.
    """
    if value is None:
        if spec.optional:
            return
        raise TypeError(f"{where} must not be None")
    if spec.kind == "hyperparameter":
        if isinstance(value, jax.core.Tracer):
            return
        if not (isinstance(value, jax.Array | np.ndarray) and value.ndim == 0):
            shape = getattr(value, "shape", None)
            what = f"an array of shape {tuple(shape)}" if shape is not None else repr(value)
            raise TypeError(f"{where} must be a real number; got {what}")
        if not jnp.issubdtype(value.dtype, jnp.floating):
            raise TypeError(f"{where} must be a real number; got dtype {value.dtype}")
        v = float(value)
        if not math.isfinite(v) and not (math.isinf(v) and v > 0 and spec.upper is None):
            raise ValueError(f"{where} must be finite; got {v}")
        _check_bounds(where, v, spec)
        return
    if spec.kind == "vector":
        if isinstance(value, jax.core.Tracer):
            return
        if not isinstance(value, jax.Array | np.ndarray):
            raise TypeError(f"{where} must be {spec.length} real numbers; got {value!r}")
        if value.shape != (spec.length,):
            raise ValueError(f"{where} must have shape ({spec.length},); got {tuple(value.shape)}")
        v = np.asarray(value, dtype=float)
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{where} must be finite; got {v.tolist()}")
        for x in v:
            _check_bounds(where, float(x), spec)
        return
    if spec.kind == "bool":
        if not isinstance(value, bool | np.bool_):
            raise TypeError(f"{where} must be true or false; got {value!r}")
        return
    if spec.kind == "str":
        if not isinstance(value, str):
            raise TypeError(f"{where} must be a string; got {value!r}")
        if spec.choices is not None and value not in spec.choices:
            raise ValueError(f"{where} must be one of {spec.choices}; got {value!r}")
        return
    if spec.kind == "int":
        if isinstance(value, bool | np.bool_) or not isinstance(value, int | np.integer):
            raise TypeError(f"{where} must be an integer; got {value!r}")
        _check_bounds(where, int(value), spec)
        return
    if spec.kind == "float":
        if isinstance(value, bool | np.bool_) or not isinstance(value, int | float | np.number):
            raise TypeError(f"{where} must be a number; got {value!r}")
        if not math.isfinite(float(value)):
            raise ValueError(f"{where} must be finite; got {value!r}")
        _check_bounds(where, float(value), spec)
        return
    raise AssertionError(f"unknown field kind {spec.kind!r}")  # pragma: no cover


def check_lower_bound(name: str, value: Any, lower: float, *, open_: bool = False) -> None:
    """Raise a ``ValueError`` naming ``name`` where a concrete scalar function argument is not
    ``>= lower`` (``> lower`` with ``open_``); NaN fails. Traced values (inside ``jit`` or
    ``vmap``) and non-scalars are not checked here (configs: `check_fields`)."""
    try:
        v = float(value)
    except (TypeError, jax.errors.ConcretizationTypeError):
        return
    if not (v > lower if open_ else v >= lower):
        raise ValueError(f"{name} must be {'>' if open_ else '>='} {lower:g}; got {value}")


def check_fields(config: eqx.Module) -> None:
    """Validate every field declared with `hyperparameter` or `static` (call it from the
    config's ``__check_init__``). Fields declared otherwise (nested configs) are checked to
    have the type of their default.

    Raises:
        TypeError, ValueError: see `check_value`; the message names ``Config.field``.
    """
    name = type(config).__name__
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        spec = field_spec(f)
        where = f"{name}.{f.name}"
        if spec is not None:
            check_value(where, value, spec)
        elif isinstance(f.default, eqx.Module) and not isinstance(value, type(f.default)):
            raise TypeError(
                f"{where} must be a {type(f.default).__name__}; got {type(value).__name__}"
            )


def differentiable_fields(config: eqx.Module) -> tuple[str, ...]:
    """Names of the hyperparameters of ``config`` (not of nested configs) declared
    differentiable."""
    return tuple(
        f.name
        for f in dataclasses.fields(config)
        if (s := field_spec(f)) is not None and s.kind == "hyperparameter" and s.differentiable
    )


def threshold_fields(config: eqx.Module) -> tuple[str, ...]:
    """Names of the hyperparameters of ``config`` declared piecewise constant (thresholds)."""
    return tuple(
        f.name
        for f in dataclasses.fields(config)
        if (s := field_spec(f)) is not None and s.kind == "hyperparameter" and not s.differentiable
    )
