"""Gradient-based tuning of the chain's hyperparameters on scenes with ground truth.

`tune` differentiates a supervised loss through `estimate_disparity_arrays` (the same chain
and the same defaults as `estimate_disparity`) with respect to chosen differentiable fields
of a `PipelineConfig`, and takes Adam steps (optax). It returns a `PipelineConfig` that
`estimate_disparity` and ``mvedge depth --config`` accept (`config_to_toml`).
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, Float

from .._memory import CHAIN_MAPPINGS, ensure_mapping_headroom
from ..edges import check_cross_hair
from ..lightfield import LightField
from ._chain import estimate_disparity_arrays
from ._compile import STAGE_CACHE
from ._config import (
    PipelineConfig,
    get_path,
    hyperparameter_paths,
    path_spec,
    replace_paths,
    with_values,
)

LOSSES = ("l1", "mse")


def _parametrisation(config: PipelineConfig, path: str) -> tuple[bool, float, float]:
    """How `tune` optimises the field at ``path``: ``(as_logarithm, low, high)``.

    A field bounded below by 0 (open or closed) whose value is above 0 is optimised as its
    logarithm (Adam's steps are then relative changes); any other field directly. ``low`` and
    ``high`` bound the optimised parameter: the field's bounds (an open bound moved inside by
    one ulp of float32), and for a logarithm the range whose exponential stays a finite,
    normal float32.
    """
    spec = path_spec(config, path)
    lower = None if spec is None else spec.lower
    upper = None if spec is None else spec.upper
    info = np.finfo(np.float32)
    if lower == 0.0 and float(get_path(config, path)) > 0.0:
        # 1e-6 below log(upper): exp in float32 must not round above the bound
        high = math.log(float(info.max)) if upper is None else math.log(upper) - 1e-6
        # 2 above log(tiny): XLA's float32 exp flushes to 0 at the bottom of the normal range
        return True, math.log(float(info.tiny)) + 2.0, min(high, math.log(float(info.max)))
    low = -math.inf if lower is None else float(lower)
    if lower is not None and spec.lower_open:
        low = float(np.nextafter(np.float32(low), np.float32(np.inf)))
    return False, low, math.inf if upper is None else float(upper)


class TuneScene(eqx.Module):
    """One training scene of `tune`: arrays and the static bank range.

    Attributes:
        views: ``(U, V, H, W, 3)`` RGB in [0, 1].
        target: ``(U, V, H, W)`` ground-truth disparity (0 where unknown).
        mask: ``(U, V, H, W)`` bool, pixels with ground truth.
        d_max: the filter bank's half-range for this scene (static).
    """

    views: Float[Array, "U V H W 3"]
    target: Float[Array, "U V H W"]
    mask: Array
    d_max: float = eqx.field(static=True)

    @classmethod
    def from_light_field(cls, lf: LightField, config: PipelineConfig) -> TuneScene:
        """Bundle a light field with ground truth.

        Raises:
            ValueError: if the light field has no ground truth, or fails
                `mvedge_jax.edges.check_cross_hair`.
        """
        if lf.gt_disparity is None or not np.asarray(lf.gt_mask).any():
            raise ValueError(f"light field {lf.name!r} has no ground-truth disparity to tune on")
        d_max = check_cross_hair(lf, config.edges)
        gt = np.asarray(lf.gt_disparity)
        mask = np.asarray(lf.gt_mask)
        return cls(
            views=jnp.asarray(lf.views),
            target=jnp.asarray(np.where(mask, gt, 0.0), jnp.asarray(lf.views).dtype),
            mask=jnp.asarray(mask),
            d_max=float(d_max),
        )


def chain_loss(
    config: PipelineConfig, scene: TuneScene, *, loss: str = "l1", key: Array | None = None
) -> Float[Array, ""]:
    """Supervised loss of the chain on one scene: mean L1 (or squared) disparity error over
    every pixel of every view with ground truth.

    Differentiable with respect to the array fields of ``config`` (smoothly in those of
    `hyperparameter_paths` with ``differentiable=True``) and the views.

    Args:
        config: `PipelineConfig`.
        scene: `TuneScene`.
        loss: ``"l1"`` (thesis Sec. 7.2.3) or ``"mse"``.
        key: PRNG key of the chain (default ``jax.random.key(0)``).

    Returns:
        The scalar loss, pixels per view step (squared for ``"mse"``).

    Raises:
        ValueError: on an unknown loss.
    """
    if loss not in LOSSES:
        raise ValueError(f"loss must be one of {LOSSES}; got {loss!r}")
    key = jax.random.key(0) if key is None else key
    out = estimate_disparity_arrays(scene.views, config, key=key, d_max=scene.d_max)
    err = out.disparity - scene.target.astype(out.disparity.dtype)
    err = jnp.abs(err) if loss == "l1" else err * err
    m = scene.mask.astype(err.dtype)
    return jnp.sum(err * m) / jnp.maximum(jnp.sum(m), 1.0)


def _encode(config, paths, positive):
    """The optimised parameters: the fields' values (logarithms where ``positive[path]``) as
    strongly typed arrays. The config's leaves are weakly typed (`as_float`) while optax's
    updates are not, so without a fixed dtype the second step would trace and compile the
    chain's gradient again."""
    theta = {}
    for p in paths:
        v = jnp.asarray(get_path(config, p))
        theta[p] = jnp.asarray(jnp.log(v) if positive[p] else v, dtype=v.dtype)
    return theta


def _project(theta, bounds):
    """``theta`` clipped to ``bounds[path] = (low, high)`` (dtypes kept)."""
    return {p: jnp.clip(v, *bounds[p]).astype(v.dtype) for p, v in theta.items()}


def _decode(theta, positive):
    return {p: (jnp.exp(v) if positive[p] else v) for p, v in theta.items()}


@functools.partial(jax.jit, static_argnames=("positive", "loss"))
def _loss_and_grad(theta, scene, base, key, *, positive, loss):
    """`chain_loss` of ``base`` with the decoded ``theta`` and its gradient in ``theta``.
    Module-level, with the configuration, scene and key as arguments: one compilation per
    scene shape, static configuration, set of fields and loss, reused by every step and every
    `tune` call (``positive``: sorted ``(path, optimised as a logarithm)`` pairs)."""

    def objective(theta):
        values = _decode(theta, dict(positive))
        return chain_loss(replace_paths(base, values), scene, loss=loss, key=key)

    return jax.value_and_grad(objective)(theta)


def tune(
    config: PipelineConfig,
    scenes: Sequence[LightField],
    *,
    fields: Sequence[str],
    steps: int,
    learning_rate: float = 0.05,
    loss: str = "l1",
    key: Array | None = None,
    callback: Callable[[int, dict], None] | None = None,
) -> tuple[PipelineConfig, dict[str, np.ndarray]]:
    """Tune hyperparameters of the chain by Adam on the supervised loss of ground-truth scenes.

    Every step differentiates `chain_loss`, averaged over ``scenes``, through the whole chain
    (edges → surface vectors → centre diffusion → sharpening → propagation) with respect to
    ``fields``. Fields bounded below by 0 (weights, scales, σ, ε) are optimised as
    logarithms, so a step of ``learning_rate`` is a relative change of about that much and
    they stay positive; such a field that starts at 0, and every other field, is optimised
    directly. After every step each field is projected onto its bounds, so the returned
    configuration is always valid. A step whose loss or gradient is not finite is skipped. Use
    `smooth_config` for ``edges.label.temperature`` and ``reconstruct.sharpen.wmf_sigma``, in
    which the default (hard) chain is piecewise constant. The chain's selections (boundary
    snapping, matte, the plane sweep's choice of hypothesis) stay: the loss is piecewise
    smooth, so a large step can cross choices that raise it; the sweep's hypotheses move
    with the centre map and make the most of these jumps (``reconstruct.sharpen.sweep_steps
    = 0`` removes them). The gradient is compiled once per
    scene shape, static configuration, set of ``fields`` and ``loss``, and reused by every
    step and by later calls (new starting values, learning rates or step counts do not
    recompile); the values are traced.

    Args:
        config: the starting `PipelineConfig`.
        scenes: light fields with ground truth (every view's, or the centre view's).
        fields: dotted paths of differentiable fields, e.g. ``["reconstruct.centre.omega",
            "surface.gradient_sigma"]`` (`hyperparameter_paths` with
            ``differentiable=True``).
        steps: Adam steps (>= 0).
        learning_rate: Adam learning rate.
        loss: ``"l1"`` or ``"mse"`` (`chain_loss`).
        key: PRNG key of the chain.
        callback: called as ``callback(step, record)`` after every step; ``record`` holds
            ``loss``, ``grad_norm``, ``seconds``, ``skipped`` and the field values (floats)
            at the step's start.

    Returns:
        ``(config, history)``: the tuned `PipelineConfig` and per-step NumPy arrays
        ``loss``, ``grad_norm``, ``seconds``, ``skipped`` and one per field (values at the
        step's start), plus ``final_loss``.

    Raises:
        ValueError: on an empty scene list, a field that is not a differentiable
            hyperparameter, ``steps < 0``, a non-positive learning rate, or a scene without
            ground truth.

    References:
        Thesis Sec. 7.2.3 (supervised L1); Kingma & Ba, "Adam", ICLR 2015.
    """
    differentiable = set(hyperparameter_paths(config, differentiable=True))
    fields = list(fields)
    bad = [f for f in fields if f not in differentiable]
    if bad:
        raise ValueError(
            f"not differentiable hyperparameters: {bad}; choose from "
            f"hyperparameter_paths(differentiable=True)"
        )
    if not fields:
        raise ValueError("fields is empty: name at least one hyperparameter to tune")
    if not scenes:
        raise ValueError("scenes is empty: tune needs at least one light field with GT")
    if not (isinstance(steps, int) and steps >= 0):
        raise ValueError(f"steps must be an int >= 0; got {steps!r}")
    if not (math.isfinite(learning_rate) and learning_rate > 0):
        raise ValueError(f"learning_rate must be finite and > 0; got {learning_rate}")
    if loss not in LOSSES:
        raise ValueError(f"loss must be one of {LOSSES}; got {loss!r}")
    ensure_mapping_headroom(CHAIN_MAPPINGS, release=STAGE_CACHE.clear)
    prepared = [TuneScene.from_light_field(lf, config) for lf in scenes]
    param = {p: _parametrisation(config, p) for p in fields}
    positive = {p: param[p][0] for p in fields}
    bounds = {p: param[p][1:] for p in fields}
    key = jax.random.key(0) if key is None else key

    signs = tuple(sorted(positive.items()))

    def total(theta):
        vals, grads = zip(
            *(_loss_and_grad(theta, s, config, key, positive=signs, loss=loss) for s in prepared),
            strict=True,
        )
        n = len(prepared)
        g = jax.tree.map(lambda *xs: sum(xs) / n, *grads)
        return sum(float(v) for v in vals) / n, g

    opt = optax.adam(learning_rate)
    theta = _encode(config, fields, positive)
    state = opt.init(theta)
    hist: dict[str, list] = {k: [] for k in ("loss", "grad_norm", "seconds", "skipped", *fields)}
    for step in range(steps):
        t0 = time.perf_counter()
        value, g = total(theta)
        gnorm = float(optax.tree.norm(g))
        ok = math.isfinite(value) and math.isfinite(gnorm)
        record = {p: float(v) for p, v in _decode(theta, positive).items()}
        if ok:
            updates, state = opt.update(g, state, theta)
            theta = _project(optax.apply_updates(theta, updates), bounds)
        record.update(
            loss=value, grad_norm=gnorm, seconds=time.perf_counter() - t0, skipped=float(not ok)
        )
        for k in hist:
            hist[k].append(record[k])
        if callback is not None:
            callback(step, record)
    final, _ = total(theta)
    tuned = with_values(config, {p: float(v) for p, v in _decode(theta, positive).items()})
    history = {k: np.asarray(v) for k, v in hist.items()}
    history["final_loss"] = np.asarray(final)
    return tuned, history
