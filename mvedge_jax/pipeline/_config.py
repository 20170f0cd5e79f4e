"""`PipelineConfig`: the configuration of the whole chain, one frozen config per stage, and
its TOML form."""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import numpy as np

from .._fields import as_float, field_spec
from ..diff import ModelConfig, OptimizeConfig, RenderConfig
from ..edges import EdgeConfig
from ..reconstruct import ReconstructConfig
from ..surface import SurfaceConfig
from ._checks import ConfigError, ConfigTypeError, override_config

#: The default of ``PipelineConfig.optimize``: the thesis schedule and losses (Sec. 7.1.5) with
#: settings that suit a start from the Ch. 6 result (dense, accurate labels): a narrower
#: splat (σ_S = 0.8, σ_λ = 0.5 instead of 1.3, 0.71) and stronger image-edge stops
#: (``q_scale`` 30) encode the Ch. 6 map faithfully; a low density ρ = 0.1 keeps visible
#: neighbours from hiding each other; larger tile capacities avoid overflow with dense
#: points; one pass at about half the authors' learning rates (Adam moves every label by
#: about the learning rate per step). The measurements behind these values are in
#: docs/RESULTS.md. ``OptimizeConfig()`` is the thesis configuration.
OPTIMIZE_DEFAULT = OptimizeConfig(
    model=ModelConfig(
        render=RenderConfig(
            sigma_label=0.8,
            sigma_weight=0.5,
            density=0.1,
            tile_levels=((128, 1.0), (200, 0.5)),
        ),
        q_scale=30.0,
    ),
    passes=1,
    learning_rate=(0.008, 0.05, 0.005, 0.005),
)


class PipelineConfig(eqx.Module):
    """Configuration of the whole pipeline: one frozen config per stage.

    Attributes:
        edges: multi-view edge detection (Ch. 4.1).
        surface: surface vectors and depth-edge confidence (Ch. 4.2–4.3).
        reconstruct: smooth 4D reconstruction (Ch. 6); its cross-hair/off-cross-hair part
            also propagates an optimised centre map (`optimize_disparity`).
        optimize: the optional Ch. 7 refinement (`optimize_disparity`, ``mvedge depth
            --optimize``); default `OPTIMIZE_DEFAULT` (``OptimizeConfig()`` is the thesis
            configuration).
    """

    edges: EdgeConfig = EdgeConfig()
    surface: SurfaceConfig = SurfaceConfig()
    reconstruct: ReconstructConfig = ReconstructConfig()
    optimize: OptimizeConfig = OPTIMIZE_DEFAULT


_STAGE_FIELDS = ("edges", "surface", "reconstruct")


def _hyperparameter_fields(config: eqx.Module, prefix: str, differentiable: bool | None):
    """Dotted paths of the hyperparameters of ``config`` and of its nested configs."""
    out = []
    for f in dataclasses.fields(config):
        spec = field_spec(f)
        if spec is None:
            value = getattr(config, f.name)
            if isinstance(value, eqx.Module):
                out += _hyperparameter_fields(value, f"{prefix}.{f.name}", differentiable)
            continue
        if spec.kind != "hyperparameter":
            continue
        if differentiable is None or spec.differentiable == differentiable:
            out.append(f"{prefix}.{f.name}")
    return out


def hyperparameter_paths(
    config: PipelineConfig | None = None, *, differentiable: bool | None = None
) -> tuple[str, ...]:
    """Dotted paths (``"edges.filter.presmooth_sigma"``) of the chain's scalar
    hyperparameters.

    Args:
        config: the configuration whose stage configs are listed (default
            `PipelineConfig()`; only the field declarations matter).
        differentiable: ``True``: only the fields the chain is smooth in; ``False``: only the
            thresholds (piecewise constant); ``None``: all.

    Returns:
        The paths, stage by stage and sub-config by sub-config in declaration order.
    """
    config = PipelineConfig() if config is None else config
    out = []
    for stage in _STAGE_FIELDS:
        out += _hyperparameter_fields(getattr(config, stage), stage, differentiable)
    return tuple(out)


def get_path(config: eqx.Module, path: str):
    """The value at a dotted path, e.g. ``get_path(config, "edges.filter.presmooth_sigma")``."""
    value = config
    for part in path.split("."):
        value = getattr(value, part)
    return value


def path_spec(config: eqx.Module, path: str):
    """The declared `FieldSpec` (type, bounds, differentiability) of the field at a dotted
    path, or ``None`` for a field declared without one.

    Raises:
        AttributeError: where the path names no config or no field of it.
    """
    owner, _, name = path.rpartition(".")
    parent = get_path(config, owner) if owner else config
    for f in dataclasses.fields(parent):
        if f.name == name:
            return field_spec(f)
    raise AttributeError(f"{type(parent).__name__} has no field {name!r} (path {path!r})")


def replace_paths(config: eqx.Module, values: dict) -> eqx.Module:
    """``config`` with the fields at the dotted paths of ``values`` replaced (traceable: the
    values may be tracers, so this works inside ``jit``, ``grad`` and ``vmap``; numbers
    become 0-d array leaves).

    Raises:
        AttributeError: on a path that names no field.
    """
    paths = list(values)
    for path in paths:
        get_path(config, path)  # raises on a bad path

    def where(c):
        return tuple(get_path(c, p) for p in paths)

    # Python numbers become array leaves (as the constructors make them): a number left as a
    # Python scalar would be a compile-time constant of every jitted stage.
    return eqx.tree_at(where, config, tuple(as_float(values[p]) for p in paths))


def _rebuilt(config: eqx.Module, values: dict) -> eqx.Module:
    """``config`` rebuilt through its constructor with ``values`` at paths relative to it
    (nested configs are rebuilt through theirs)."""
    direct, nested = {}, {}
    for path, value in values.items():
        head, _, rest = path.partition(".")
        if rest:
            nested.setdefault(head, {})[rest] = value
        else:
            direct[head] = value
    for head, sub in nested.items():
        direct[head] = _rebuilt(getattr(config, head), sub)
    return dataclasses.replace(config, **direct)


def with_values(config: PipelineConfig, values: dict) -> PipelineConfig:
    """``config`` with concrete new values at dotted paths, rebuilt through the stage
    configs' and sub-configs' constructors (so the values are converted and validated,
    unlike `replace_paths`).

    Raises:
        AttributeError: on a path that names no field of a stage config
            (``stage.sub.field``, or ``stage.field`` for a field of the stage config itself).
        TypeError, ValueError: on a value the field does not accept.
    """
    for path in values:
        stage, _, name = path.partition(".")
        if stage not in _STAGE_FIELDS or not name:
            raise AttributeError(f"{path!r} is not a field of a stage config (stage.sub.field)")
        get_path(config, path)
    return _rebuilt(config, values)


def smooth_config(config: PipelineConfig | None = None) -> PipelineConfig:
    """``config`` with the smooth surrogates of its piecewise-constant stages: soft edge
    labels (``edges.label.strategy = "soft"``), the weighted mean instead of the weighted
    median (``reconstruct.sharpen.filter = "mean"``), and the cross-hair holes without the
    visibility test (``reconstruct.epi.visibility_fill = False``: the test switches a hole
    between candidate values, so the all-view loss jumps as the inpainting's fields move).
    Use it to differentiate the chain with respect to ``edges.label.temperature`` and
    ``reconstruct.sharpen.wmf_sigma`` (the chain is piecewise constant in them otherwise), or
    for gradient-based tuning (`tune`).

    Args:
        config: the configuration to modify (default `PipelineConfig()`).

    Returns:
        The `PipelineConfig` with ``edges.label.strategy = "soft"``,
        ``reconstruct.sharpen.filter = "mean"`` and ``reconstruct.epi.visibility_fill =
        False``, other fields unchanged.
    """
    config = PipelineConfig() if config is None else config
    return with_values(
        config,
        {
            "edges.label.strategy": "soft",
            "reconstruct.sharpen.filter": "mean",
            "reconstruct.epi.visibility_fill": False,
        },
    )


CONFIG_TABLES = ("edges", "surface", "reconstruct", "optimize")


def config_from_dict(data: dict, *, source: str | None = None) -> PipelineConfig:
    """Build a `PipelineConfig` from ``{"edges": {...}, "surface": {...}, "reconstruct": {...},
    "optimize": {...}}`` (keyword arguments of the stage configs; missing tables and keys keep
    the defaults).

    Nested configs are sub-tables, e.g. in TOML ``[edges.filter]`` (`FilterConfig`),
    ``[reconstruct.epi.solver]``, ``[optimize.loss]`` (``LossConfig``), ``[optimize.model]``
    or ``[optimize.model.render]``; arrays become tuples (``blocks``, ``learning_rate``,
    ``tile_levels``). Every value is checked against the type of the field's default
    (`override_config`): ``"false"`` is not a boolean, an array is not a number.

    Args:
        data: the tables.
        source: the file they came from, named in every error message.

    Raises:
        ValueError: on an unknown table name or a bad parameter value (`ConfigError`).
        TypeError: on an unknown parameter or a value of the wrong type (`ConfigTypeError`,
            also a `ValueError`).
    """
    where = f"{source}: " if source else ""
    if not isinstance(data, dict):
        raise ConfigTypeError(f"{where}the configuration must be a table of tables")
    unknown = set(data) - set(CONFIG_TABLES)
    if unknown:
        raise ConfigError(
            f"{where}unknown config tables {sorted(unknown)}; use {', '.join(CONFIG_TABLES)}"
        )
    base = PipelineConfig()
    return PipelineConfig(
        **{
            name: override_config(getattr(base, name), data.get(name, {}), name, source)
            for name in CONFIG_TABLES
        }
    )


def _plain(value):
    """A config value as TOML data: configs → tables, 0-d arrays → floats, tuples → arrays."""
    if isinstance(value, eqx.Module):
        out = {}
        for f in dataclasses.fields(value):
            v = getattr(value, f.name)
            if v is not None:
                out[f.name] = _plain(v)
        return out
    if isinstance(value, jax.Array | np.ndarray | np.generic):
        arr = np.asarray(value)
        if arr.ndim == 0 and arr.dtype == np.float32:
            return float(str(arr[()]))  # the shortest decimal that reads back as this float32
        if arr.ndim == 0:
            return arr.item()
        return arr.tolist()
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def config_to_dict(config: PipelineConfig) -> dict:
    """Every field of a `PipelineConfig` as nested plain data (the tables of its TOML form;
    fields that are ``None`` are left out, which reads back as their default ``None``).

    Raises:
        ValueError: if a field is ``None`` where its default is not (TOML has no null).
    """
    data = _plain(config)
    base = _plain(PipelineConfig())

    def check(d, b, where):
        for k, v in b.items():
            if k not in d:
                raise ValueError(f"{where}{k} is None, which TOML cannot write")
            if isinstance(v, dict):
                check(d[k], v, f"{where}{k}.")

    check(data, base, "")
    return data


def config_to_toml(config: PipelineConfig) -> str:
    """The TOML text of a `PipelineConfig`, every field written (`config_to_dict`); reading
    it back with `config_from_toml` (or ``mvedge depth --config``) gives the same config."""
    import tomli_w

    return tomli_w.dumps(config_to_dict(config))


def config_from_toml(text: str) -> PipelineConfig:
    """A `PipelineConfig` from TOML text (`config_from_dict` of its tables).

    Raises:
        ValueError: on invalid TOML (``tomllib.TOMLDecodeError``) or a bad value.
        TypeError: on an unknown parameter or a value of the wrong type.
    """
    import tomllib

    return config_from_dict(tomllib.loads(text))
