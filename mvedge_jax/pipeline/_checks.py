"""Guards of the main job: strict configuration overrides, memory bounds before allocating,
and checks of a result that would otherwise be quietly wrong (no edge points, unconverged or
non-finite solves)."""

from __future__ import annotations

import dataclasses
import math
import os

import equinox as eqx
import numpy as np

from ..edges import EdgeConfig, bank_width, resolve_d_max


class ConfigError(ValueError):
    """A configuration value or key that cannot be used (the message names key and file)."""


class ConfigTypeError(ConfigError, TypeError):
    """A configuration value of the wrong type, or an unknown key."""


def _where(source: str | None) -> str:
    return f"{source}: " if source else ""


def _type_hints(cls) -> dict[str, str]:
    """Field annotations as strings (``from __future__ import annotations`` keeps them so)."""
    out: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        for k, v in getattr(klass, "__annotations__", {}).items():
            out[k] = v if isinstance(v, str) else getattr(v, "__name__", repr(v))
    return out


def _kind(current, annotation: str) -> str:
    """What a field holds, from its current value (or its annotation when that is None)."""
    if isinstance(current, eqx.Module):
        return "table"
    if isinstance(current, bool | np.bool_):
        return "bool"
    if isinstance(current, int | np.integer):
        return "int"
    if isinstance(current, float | np.floating):
        return "float"
    if isinstance(current, str):
        return "str"
    if isinstance(current, tuple):
        return "tuple"
    if hasattr(current, "shape") and hasattr(current, "dtype"):
        if tuple(current.shape) != ():
            return "array"
        dt = np.dtype(current.dtype)
        if dt == np.bool_:
            return "bool"
        return "int" if np.issubdtype(dt, np.integer) else "float"
    if current is None:
        head = annotation.replace(" ", "").split("|")
        for kind in ("bool", "int", "float", "str", "tuple"):
            if any(h == kind or h.startswith(kind + "[") for h in head):
                return kind
    return "any"


def _describe(value) -> str:
    if isinstance(value, list | tuple):
        return f"an array {value!r}"
    if isinstance(value, dict):
        return "a table"
    return f"{value!r} ({type(value).__name__})"


_EXPECT = {
    "bool": "true or false (a TOML boolean, not a string)",
    "int": "an integer",
    "float": "a number",
    "str": "a string",
    "tuple": "an array",
    "table": "a table",
}


def _checked(value, current, kind: str, key: str, source: str | None):
    """``value`` converted for a field of the given kind, or a `ConfigTypeError`."""

    def fail():
        got = _describe(value)
        raise ConfigTypeError(f"{_where(source)}{key} expects {_EXPECT[kind]}; got {got}")

    if kind == "bool":
        if not isinstance(value, bool | np.bool_):
            fail()
        return bool(value)
    if kind == "int":
        if isinstance(value, bool | np.bool_) or not isinstance(value, int | np.integer):
            fail()
        return int(value)
    if kind == "float":
        if isinstance(value, bool | np.bool_) or not isinstance(value, int | float | np.number):
            fail()
        v = float(value)
        default_finite = current is None or math.isfinite(float(np.asarray(current)))
        if math.isnan(v) or (math.isinf(v) and default_finite):
            raise ConfigError(f"{_where(source)}{key} must be a finite number; got {value!r}")
        return v
    if kind == "str":
        if not isinstance(value, str):
            fail()
        return value
    if kind == "tuple":
        if not isinstance(value, list | tuple):
            fail()
        proto = current[0] if isinstance(current, tuple) and current else None
        if proto is None:
            return _tuples(value)
        return tuple(_element(v, proto, f"{key}[{i}]", source) for i, v in enumerate(value))
    if kind == "array":
        shape = tuple(current.shape)
        if isinstance(value, dict | str | bool) or np.shape(value) not in ((), shape):
            raise ConfigTypeError(
                f"{_where(source)}{key} expects a number or an array of shape {shape}; got "
                f"{_describe(value)}"
            )
        arr = np.asarray(value)
        if arr.dtype == object or not np.issubdtype(arr.dtype, np.number):
            raise ConfigTypeError(f"{_where(source)}{key} expects numbers; got {_describe(value)}")
        if not np.isfinite(arr).all():
            raise ConfigError(f"{_where(source)}{key} must be finite; got {value!r}")
        return _tuples(value)
    return _tuples(value)


def _element(value, proto, key: str, source: str | None):
    """One element of a tuple field, checked against the default's first element."""
    if isinstance(proto, tuple):
        if not isinstance(value, list | tuple):
            raise ConfigTypeError(f"{_where(source)}{key} expects an array; got {_describe(value)}")
        if len(proto) == len(value):
            pairs = enumerate(zip(value, proto, strict=True))
            return tuple(_element(v, p, f"{key}[{i}]", source) for i, (v, p) in pairs)
        return _tuples(value)
    return _checked(value, proto, _kind(proto, ""), key, source)


def _tuples(value):
    """TOML arrays → tuples (static config fields must be hashable)."""
    if isinstance(value, list | tuple):
        return tuple(_tuples(v) for v in value)
    return value


def override_config(base: eqx.Module, table: dict, key: str, source: str | None = None):
    """``base`` with the fields named in ``table`` replaced, every value type-checked against
    the field's default (or its annotation when the default is None).

    Booleans must be TOML booleans (``"false"`` is refused), integers integers, numbers
    finite numbers (``inf`` only where the default is infinite), arrays arrays; a number
    field (or a 0-d array field) refuses an array. Sub-tables override nested configs and
    keep their other values.

    Args:
        base: a config (an ``eqx.Module`` dataclass).
        table: ``{field: value}``.
        key: dotted name of ``base`` for messages (e.g. ``"optimize.model"``).
        source: file the table came from, for messages.

    Raises:
        ConfigTypeError: (a `TypeError` and `ValueError`) on an unknown key or a value of
            the wrong type; the message names the key and the file.
        ConfigError: on a value the config itself refuses (its ``__check_init__``).
    """
    if not isinstance(table, dict):
        raise ConfigTypeError(f"{_where(source)}{key} expects a table; got {_describe(table)}")
    fields = {f.name: f for f in dataclasses.fields(base) if f.init}
    hints = _type_hints(type(base))
    kwargs = {}
    for name, value in table.items():
        full = f"{key}.{name}"
        if name not in fields:
            raise ConfigTypeError(
                f"{_where(source)}unknown key {full}; {type(base).__name__} has "
                f"{', '.join(sorted(fields))}"
            )
        current = getattr(base, name, None)
        kind = _kind(current, hints.get(name, ""))
        if kind == "table":
            kwargs[name] = override_config(current, value, full, source)
        else:
            kwargs[name] = _checked(value, current, kind, full, source)
    try:
        return dataclasses.replace(base, **kwargs)
    except ConfigError:
        raise
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{_where(source)}[{key}] {e}") from None


# ---- memory ---------------------------------------------------------------------------------


def memory_limit() -> int:
    """Bytes a run may use: ``$MVEDGE_MEMORY_LIMIT_GB`` if set, else 80% of the device's
    memory (accelerators) or of the physical memory (CPU)."""
    env = os.environ.get("MVEDGE_MEMORY_LIMIT_GB")
    if env:
        return int(float(env) * 2**30)
    import jax

    stats = None
    try:
        stats = jax.devices()[0].memory_stats()
    except Exception:
        pass
    if stats and stats.get("bytes_limit"):
        return int(0.8 * stats["bytes_limit"])
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return 1 << 62
    return int(0.8 * total)


def _gib(n: float) -> str:
    return f"{n / 2**30:.1f} GiB"


def edge_memory_estimate(
    config: EdgeConfig,
    grid: tuple[int, int],
    size: tuple[int, int],
    disparity_range: tuple[float, float] | None,
) -> tuple[int, str]:
    """Bytes of the largest buffers of edge detection, and the value that drives them.

    The filter bank of each EPI direction is ``(n_filters, h, Fw)`` float32 with ``Fw``
    growing with ``d_max`` times the number of views; the bank convolution of a chunk of
    EPIs holds ``chunk`` padded EPIs of width ``W + Fw`` and their responses to every filter.

    Returns:
        ``(bytes, description of the driving values)``.
    """
    d_max = resolve_d_max(config, disparity_range)
    fc = config.filter
    U, V = grid
    H, W = size
    total, widths = 0, []
    for n_views, length in ((V, W), (U, H)):
        h = n_views if n_views % 2 else n_views + 1
        fw = bank_width(h, d_max, 1.5) + 2
        widths.append(fw)
        bank = fc.n_filters * h * fw * 4
        chunk = min(fc.chunk, length)
        conv = chunk * (h * (length + fw) * 3 + fc.n_filters * length * 3) * 4
        total = max(total, 2 * bank + conv)
    src = (
        "d_max"
        if fc.d_max is not None
        else ("the scene's disparity range" if disparity_range is not None else "d_max_fallback")
    )
    why = (
        f"filter bank of {fc.n_filters} filters (n_filters) × {max(widths)} px wide "
        f"(from d_max = {d_max:g} px/view, set by {src}), chunk = {fc.chunk}"
    )
    return int(total), why


def check_memory(config, grid, size, disparity_range, *, views_bytes: int = 0) -> None:
    """Refuse a configuration whose edge detection cannot fit in memory, before anything
    is allocated (e.g. ``edges.filter.d_max_fallback = 1e6``).

    Raises:
        ConfigError: naming the estimate, the limit and the values that drive it.
    """
    need, why = edge_memory_estimate(config.edges, grid, size, disparity_range)
    limit = memory_limit()
    if need + views_bytes > limit:
        raise ConfigError(
            f"edge detection would need about {_gib(need + views_bytes)} for {grid[0]}x{grid[1]} "
            f"views of {size[0]}x{size[1]} px, more than the {_gib(limit)} available: {why}. "
            "Lower edges.filter.d_max / d_max_fallback, n_filters or chunk"
        )


def check_memory_before_loading(config, path, *, views=None, scale=None) -> None:
    """`check_memory` from a light-field folder's layout alone (no pixels read): the grid
    (after the ``views`` crop), the metadata disparity range (times ``scale``) and the
    smallest accepted view size, i.e. a lower bound of the real need.

    Raises:
        ConfigError: if even that lower bound exceeds the memory limit.
    """
    from ..io import MIN_VIEW_SIZE, crop_window, detect_layout

    try:
        info = detect_layout(path)
        grid = crop_window(info.grid, None if views is None else tuple(views))[2:]
    except (OSError, ValueError, TypeError):
        return  # the loader reports this
    drange = info.disparity_range
    if drange is not None and scale is not None:
        drange = (drange[0] * scale, drange[1] * scale)
    try:
        check_memory(config, grid, (MIN_VIEW_SIZE, MIN_VIEW_SIZE), drange)
    except ConfigError:
        raise
    except ValueError:
        return  # e.g. d_max below the scene's range: reported by the pipeline


def check_compiled_memory(stage: str, compiled) -> None:
    """Refuse to run a compiled stage whose buffers exceed `memory_limit` (XLA's own
    figures: arguments, outputs and temporaries).

    Raises:
        ConfigError: naming the stage and the sizes.
    """
    try:
        m = compiled.memory_analysis()
    except Exception:  # backends without memory analysis
        return
    if m is None:
        return
    need = int(m.argument_size_in_bytes + m.output_size_in_bytes + m.temp_size_in_bytes)
    limit = memory_limit()
    if need > limit:
        raise ConfigError(
            f"stage {stage!r} would need {_gib(need)} ({_gib(m.temp_size_in_bytes)} of "
            f"temporaries), more than the {_gib(limit)} available; reduce the size-driving "
            "settings of that stage (capacities, chunks, radii) or the light field (--scale, "
            "--views)"
        )


# ---- results --------------------------------------------------------------------------------

#: Fewer valid edge points per pixel of the centre view than this is warned about.
MIN_EDGE_FRACTION = 1e-3


def check_edges(name: str, n_points: int, size: tuple[int, int]) -> list[str]:
    """Warnings about a light field with almost no edge points.

    Raises:
        ValueError: if there is no edge point at all (the disparity map would be a constant
            guess, not an estimate).
    """
    H, W = size
    if n_points == 0:
        raise ValueError(
            f"no edge point was found in light field {name!r} ({H}x{W} px): it is flat, "
            "blank or too small, and its disparity cannot be estimated"
        )
    if n_points < MIN_EDGE_FRACTION * H * W:
        return [
            f"only {n_points} edge points in {H}x{W} px (fewer than "
            f"{MIN_EDGE_FRACTION:g} per pixel): the disparity map is mostly interpolated "
            "and unreliable"
        ]
    return []


#: A warning is raised when more than this fraction of the valid edge points carry a label
#: within one filter spacing of the bank's end ``±d_max``.
MAX_SATURATED_FRACTION = 0.01


def check_range_saturation(
    name: str, disparity, valid, d_max: float, n_filters: int
) -> tuple[float, list[str]]:
    """Detect a filter bank narrower than the scene from the edge labels alone (no ground
    truth needed).

    An edge whose true disparity lies beyond ``±d_max`` takes the label of the outermost
    filter, so labels pile up at the bank's end. With a bank that covers the scene, no label
    lies within one filter spacing of ``±d_max`` (the default ``d_margin`` keeps the range's
    own extremes a margin inside): on HCI backgammon, dino and antinous with their metadata
    range the fraction is 0, and with that range scaled by 0.5 it is 3–12%.

    Args:
        name: the light field's name (for the message).
        disparity: ``(N,)`` edge labels, pixels per view step.
        valid: ``(N,)`` bool.
        d_max: the bank's half-range, pixels per view step.
        n_filters: filters in the bank (their spacing is ``2 d_max / (n_filters − 1)``).

    Returns:
        ``(fraction, warnings)``: the fraction of valid points within one spacing of
        ``±d_max``, and a warning when it exceeds `MAX_SATURATED_FRACTION`.
    """
    d = np.asarray(disparity, np.float64)[np.asarray(valid, bool)]
    if d.size == 0:
        return 0.0, []
    spacing = 2.0 * d_max / (n_filters - 1)
    frac = float(np.mean(np.abs(d) >= d_max - spacing))
    if frac <= MAX_SATURATED_FRACTION:
        return frac, []
    return frac, [
        f"{100.0 * frac:.1f}% of the edge points of {name!r} have a disparity at the end of "
        f"the filter bank (|d| within {spacing:.3g} of d_max = {d_max:.3g} px per view step): "
        "the scene's disparity range is probably wider than the one used; give a wider range "
        "(edges.filter.d_max, or fix the range in the scene's metadata)"
    ]


def check_solver(stage: str, residual, rtol: float) -> tuple[dict, list[str]]:
    """The status of a stage's linear solves from their relative residuals.

    Returns:
        ``({"status": ..., "residual_max": ...}, warnings)`` with status ``"converged"``,
        ``"max-steps"`` (some residual above ``rtol``) or ``"non-finite"`` (``residual_max``
        is then None).
    """
    r = np.asarray(residual, np.float64).ravel()
    if r.size == 0:
        return {"status": "converged", "residual_max": 0.0}, []
    if not np.isfinite(r).all():
        return {"status": "non-finite", "residual_max": None}, [
            f"{stage} solve produced NaN/Inf (non-finite input weights or targets)"
        ]
    worst = float(r.max())
    # the PCG stops when the true residual meets rtol; allow float32 rounding of the recompute
    if worst > 2.0 * rtol:
        return {"status": "max-steps", "residual_max": worst}, [
            f"{stage} solve did not converge: relative residual {worst:.3g} > rtol {rtol:g} "
            "(raise its solver's max_iters)"
        ]
    return {"status": "converged", "residual_max": worst}, []


def check_disparity(name: str, disparity) -> None:
    """Raise if a disparity map holds NaN/Inf (never write such a map quietly)."""
    d = np.asarray(disparity)
    bad = ~np.isfinite(d)
    if bad.any():
        raise ValueError(
            f"the disparity of {name!r} has {int(bad.sum())} NaN/Inf values "
            f"({100.0 * bad.mean():.1f}%); refusing to write it"
        )


def diagnose(lf, config, edges, surface, reconstruction, *, d_max: float) -> dict:
    """Checks of a finished `estimate_disparity` run, for ``metrics.json`` and the console.

    Args:
        lf, config: the run's light field and `PipelineConfig`.
        edges, surface, reconstruction: its edge set, surface result and `Reconstruction`.
        d_max: the filter bank's half-range used (pixels per view step).

    Returns:
        ``{"warnings": [str, ...], "saturated_fraction": float, "solver": {stage: {"status",
        "residual_max"}}}`` with stages ``"surface"``, ``"reconstruct.centre"``,
        ``"reconstruct.epi"`` and (with off-cross-hair views filled by a solve)
        ``"reconstruct.fill"`` (`check_range_saturation` gives the fraction).

    Raises:
        ValueError: if there is no edge point at all, or the disparity holds NaN/Inf.
    """
    warnings = check_edges(lf.name, int(np.asarray(edges.valid).sum()), lf.size)
    saturated, more = check_range_saturation(
        lf.name, edges.disparity, edges.valid, d_max, config.edges.filter.n_filters
    )
    warnings += more
    status, more = check_solver("surface", surface.residual, float(config.surface.solver.rtol))
    warnings += more
    rec_status, more = reconstruct_solver_status(reconstruction, config)
    warnings += more
    solver = {"surface": status, **rec_status}
    check_disparity(lf.name, reconstruction.disparity)
    return {"warnings": warnings, "saturated_fraction": saturated, "solver": solver}


def reconstruct_solver_status(reconstruction, config) -> tuple[dict, list[str]]:
    """``({"reconstruct.centre" | "reconstruct.epi" | "reconstruct.fill": {"status",
    "residual_max"}}, warnings)`` for the solves a `Reconstruction` reports (`check_solver`
    against each stage's ``solver.rtol``)."""
    out, warnings = {}, []
    for stage, residual in reconstruction.solver_residual.items():
        rtol = float(getattr(config.reconstruct, stage).solver.rtol)
        out[f"reconstruct.{stage}"], more = check_solver(f"reconstruct.{stage}", residual, rtol)
        warnings += more
    return out, warnings
