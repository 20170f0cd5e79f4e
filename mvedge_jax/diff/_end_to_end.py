"""End-to-end differentiable tuning: soft edge detector → splatting → diffusion → loss.

A supervised depth loss is differentiated all the way back to a handful of continuous
hyperparameters of the pipeline (issue #6, item 7; thesis Ch. 7 with the Ch. 4 detector
relaxed):

1. Soft edge detection of the central row and column of views (the Prewitt bank of Alg. 1
   on the centre row of every EPI, as `mvedge_jax.edges.soft_edge_maps`): per centre-view
   pixel and direction the filter-response magnitudes ``r_i``, ``p = softmax(r / τ)``, an
   expected disparity ``d = Σ p_i d_i``, a soft confidence ``c = Σ p_i r_i`` and a soft
   peak ratio ``ρ = c / mean_i r_i`` (how distinct the best filter is). With
   ``EndToEndConfig.temperature = "relative"`` (default) ``τ = temperature · max_i r_i``,
   which makes the softmax invariant to the image contrast (on HCI crops the best absolute
   τ differed ~4× between backgammon and antinous, the best relative one did not);
   ``"absolute"`` is exactly `soft_detect` (``τ = temperature``).
2. Edge points at *fixed* sub-pixel positions (from a hard `detect_edges` run: choosing
   positions is discrete) sample both directions' maps bilinearly. The directions are mixed
   by confidence: ``w_own = sigmoid(k log(c_own / c_other) + b)`` with ``own`` the EPI
   direction that detected the point (``b`` = ``direction_bias``; without directions,
   ``own`` = horizontal and ``b`` is ignored), ``d = w_own d_own + (1 - w_own) d_other``,
   likewise ``c`` and ``ρ``.
3. Per-point label weight ``w_p = (c_p / c̄)^γ_c (ρ_p / ρ̄)^γ_ρ`` (bars: geometric means
   over the points), i.e. ``R_p = -log w_p``; the points are rendered and diffused by
   `predict` (eq 7.2: data term ``label_weight · λ^Z``, smoothness
   ``smoothness · exp(-q_scale |∇I|)``) with the custom-VJP Poisson solve. Only the ratio
   ``label_weight / smoothness`` matters to the solution (their log-gradients are opposite).
4. `tune`: optax Adam on the supervised L1 (or MSE) against a ground-truth disparity.

Positive hyperparameters are stored as logarithms (`EndToEndParams`), so Adam steps are
relative changes and the values stay positive; exponents and the bias are plain reals.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from ..edges import (
    HORIZONTAL,
    VERTICAL,
    EdgeConfig,
    detect_edges,
    resolve_d_max,
    soft_filter_responses,
    soft_select,
)
from ..lightfield import LightField
from ._config import RenderConfig
from ._loss import supervised_loss
from ._model import (
    DiffParams,
    ModelConfig,
    Prediction,
    image_gradient_magnitude,
    predict,
    sample_bilinear,
)

#: Hyperparameters stored as logarithms (must be > 0).
POSITIVE_HPARAMS = (
    "temperature",
    "presmooth_sigma",
    "label_weight",
    "smoothness",
    "q_scale",
    "direction_power",
)
#: Hyperparameters stored as they are (any real value).
REAL_HPARAMS = ("confidence_power", "peak_power", "direction_bias")
#: All tuned hyperparameters, in the order of `EndToEndParams.values`.
HPARAM_NAMES = POSITIVE_HPARAMS + REAL_HPARAMS

_DEFAULTS = {
    "temperature": 0.1,
    "presmooth_sigma": 0.85,
    "label_weight": 100.0,
    "smoothness": 1.0,
    "q_scale": 10.0,
    "direction_power": 1.0,
    "confidence_power": 1.0,
    "peak_power": 1.0,
    "direction_bias": 0.0,
}


def _scalar(value) -> Array:
    return jnp.asarray(value, dtype=jnp.result_type(float))


class EndToEndParams(eqx.Module):
    """The tuned hyperparameters: scalar array leaves, positive ones as logarithms.

    Build from values with `EndToEndParams.create`; read values with `values`.

    Attributes:
        log_temperature: log of the softmax temperature of the soft detector (relative to
            the per-pixel maximum response, or in response units — LAB / 100 colour
            difference — with ``EndToEndConfig.temperature = "absolute"``).
        log_presmooth_sigma: log of the Gaussian pre-blur σ of the views, pixels (kernel
            half-width ``EndToEndConfig.blur_radius``).
        log_label_weight: log of the global data-term factor of eq 7.2 (`ModelConfig`).
        log_smoothness: log of the global smoothness factor of eq 7.2.
        log_q_scale: log of ``q_scale``: ``Q = q_scale · |∇I|``, ϑ = exp(-Q) (Sec. 7.1.5).
        log_direction_power: log of ``k``, the gain of the confidence ratio in the mixing of
            the two EPI directions.
        confidence_power: ``γ_c``, exponent of the soft confidence in the label weight.
        peak_power: ``γ_ρ``, exponent of the soft peak ratio in the label weight.
        direction_bias: ``b``, prior log-odds of the direction that detected a point.
    """

    log_temperature: Float[Array, ""] = eqx.field(converter=_scalar)
    log_presmooth_sigma: Float[Array, ""] = eqx.field(converter=_scalar)
    log_label_weight: Float[Array, ""] = eqx.field(converter=_scalar)
    log_smoothness: Float[Array, ""] = eqx.field(converter=_scalar)
    log_q_scale: Float[Array, ""] = eqx.field(converter=_scalar)
    log_direction_power: Float[Array, ""] = eqx.field(converter=_scalar)
    confidence_power: Float[Array, ""] = eqx.field(converter=_scalar)
    peak_power: Float[Array, ""] = eqx.field(converter=_scalar)
    direction_bias: Float[Array, ""] = eqx.field(converter=_scalar)

    def __check_init__(self):
        for field in dataclasses.fields(self):
            v = getattr(self, field.name)
            if v.shape != ():
                raise ValueError(f"EndToEndParams.{field.name} must be a scalar; got {v.shape}")
            try:
                ok = bool(np.isfinite(np.asarray(v)))
            except Exception:  # traced (vmap over hyperparameters): nothing to check
                continue
            if not ok:
                raise ValueError(f"EndToEndParams.{field.name} must be finite; got {v}")

    @classmethod
    def create(cls, **values: float) -> EndToEndParams:
        """From values; omitted ones take the defaults (temperature 0.1, presmooth_sigma
        0.85, label_weight 100, smoothness 1, q_scale 10, direction_power 1,
        confidence_power 1, peak_power 1, direction_bias 0).

        Raises:
            ValueError: on an unknown name, a non-finite value, or a value <= 0 for one of
                `POSITIVE_HPARAMS`.
        """
        unknown = set(values) - set(HPARAM_NAMES)
        if unknown:
            raise ValueError(f"unknown hyperparameters {sorted(unknown)}; known: {HPARAM_NAMES}")
        merged = {**_DEFAULTS, **values}
        kwargs = {}
        for name, v in merged.items():
            v = float(v)
            if not math.isfinite(v) or (name in POSITIVE_HPARAMS and v <= 0):
                kind = "finite and > 0" if name in POSITIVE_HPARAMS else "finite"
                raise ValueError(f"hyperparameter {name} must be {kind}; got {v}")
            if name in POSITIVE_HPARAMS:
                kwargs["log_" + name] = math.log(v)
            else:
                kwargs[name] = v
        return cls(**kwargs)

    def values(self) -> dict[str, Array]:
        """``{name: value}`` for every name of `HPARAM_NAMES` (arrays; traceable)."""
        out = {n: jnp.exp(getattr(self, "log_" + n)) for n in POSITIVE_HPARAMS}
        out.update({n: getattr(self, n) for n in REAL_HPARAMS})
        return out


_LOSSES = ("l1", "mse")
_TEMPERATURES = ("relative", "absolute")


class EndToEndConfig(eqx.Module):
    """Fixed (not tuned) settings of `end_to_end_disparity` and `tune`.

    Attributes:
        d_max: half-range of the soft detector's bank, pixels per view step (static; a
            scene's value comes from `prepare_scene`). ``None`` until it is set.
        n_filters: filters of the bank (static).
        blur_radius: half-width of the pre-blur kernel, pixels (static; bounds the useful σ).
        temperature: ``"relative"`` (τ = temperature × the pixel's largest response;
            contrast invariant) or ``"absolute"`` (τ = temperature, as `soft_detect`).
        edge_shift: Prewitt side offset, pixels (array leaf, not tuned).
        aa_sigma: anti-aliasing of the filter lines, pixels (array leaf, not tuned).
        confidence_floor: added to the soft confidences and peak ratios before their logs
            are taken (keeps flat regions finite).
        model: `ModelConfig` for rendering and the solve; its ``label_weight``,
            ``smoothness`` and ``q_scale`` are replaced by the tuned values. The default
            tile capacities hold the dense two-direction point sets of `detect_edges`
            (up to ~400 points per 8×8 tile) without overflow.
        loss: ``"l1"`` (thesis Sec. 7.2.3) or ``"mse"`` against the target disparity.

    Raises:
        ValueError: on construction, for out-of-range values.
    """

    d_max: float | None = eqx.field(static=True, default=None)
    n_filters: int = eqx.field(static=True, default=61)
    blur_radius: int = eqx.field(static=True, default=3)
    temperature: str = eqx.field(static=True, default="relative")
    edge_shift: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=1.0)
    aa_sigma: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.3)
    confidence_floor: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=1e-4)
    model: ModelConfig = ModelConfig(
        render=RenderConfig(tile_levels=((128, 1.0), (256, 0.25), (400, 0.05)))
    )
    loss: str = eqx.field(static=True, default="l1")

    def __check_init__(self):
        if self.d_max is not None and not (
            isinstance(self.d_max, (int, float)) and math.isfinite(self.d_max) and self.d_max > 0
        ):
            raise ValueError(f"EndToEndConfig.d_max must be > 0 or None; got {self.d_max!r}")
        if not (isinstance(self.n_filters, int) and self.n_filters >= 3):
            raise ValueError(
                f"EndToEndConfig.n_filters must be an int >= 3; got {self.n_filters!r}"
            )
        if not (isinstance(self.blur_radius, int) and self.blur_radius >= 1):
            raise ValueError(
                f"EndToEndConfig.blur_radius must be an int >= 1; got {self.blur_radius!r}"
            )
        if self.temperature not in _TEMPERATURES:
            raise ValueError(
                f"EndToEndConfig.temperature must be one of {_TEMPERATURES}; "
                f"got {self.temperature!r}"
            )
        if self.loss not in _LOSSES:
            raise ValueError(f"EndToEndConfig.loss must be one of {_LOSSES}; got {self.loss!r}")
        if not isinstance(self.model, ModelConfig):
            raise ValueError(f"EndToEndConfig.model must be a ModelConfig; got {self.model!r}")
        try:
            vals = {
                n: float(getattr(self, n)) for n in ("edge_shift", "aa_sigma", "confidence_floor")
            }
        except Exception:  # traced leaves: nothing to check
            return
        if not (vals["edge_shift"] > 0 and vals["confidence_floor"] > 0):
            raise ValueError(
                f"EndToEndConfig.edge_shift and confidence_floor must be > 0; got {vals}"
            )
        if not vals["aa_sigma"] >= 0:
            raise ValueError(f"EndToEndConfig.aa_sigma must be >= 0; got {vals['aa_sigma']}")


class EndToEndScene(eqx.Module):
    """One scene prepared for `tune` / `evaluate_scene` (arrays, plus the static ``d_max``).

    Attributes:
        views_row: ``(V, H, W, 3)`` the central row of views, RGB in [0, 1].
        views_col: ``(U, H, W, 3)`` the central column of views.
        centre: ``(H, W, 3)`` the centre view.
        points: ``(N, 2)`` fixed ``(x, y)`` edge positions in the centre view.
        direction: ``(N,)`` int32 EPI direction that detected each point (`HORIZONTAL` /
            `VERTICAL`).
        valid: ``(N,)`` bool point mask.
        hard_label: ``(N,)`` the hard detector's disparity of each point (reference only;
            not used by the end-to-end model).
        target: ``(H, W)`` ground-truth centre disparity, or ``None``.
        target_mask: ``(H, W)`` bool valid ground-truth pixels, or ``None``.
        d_max: the bank's half-range for this scene (static).
    """

    views_row: Float[Array, "V H W 3"]
    views_col: Float[Array, "U H W 3"]
    centre: Float[Array, "H W 3"]
    points: Float[Array, "N 2"]
    direction: Int[Array, " N"]
    valid: Bool[Array, " N"]
    hard_label: Float[Array, " N"]
    target: Float[Array, "H W"] | None
    target_mask: Bool[Array, "H W"] | None
    d_max: float = eqx.field(static=True, default=1.0)


def _check_inputs(views_row, views_col, points, centre):
    if views_row.ndim != 4 or views_row.shape[-1] != 3 or views_row.shape[0] < 3:
        raise ValueError(
            f"views_row must have shape (V >= 3, H, W, 3); got {tuple(views_row.shape)}"
        )
    H, W = views_row.shape[1:3]
    if views_col.ndim != 4 or views_col.shape[1:] != (H, W, 3) or views_col.shape[0] < 3:
        raise ValueError(
            f"views_col must have shape (U >= 3, {H}, {W}, 3); got {tuple(views_col.shape)}"
        )
    if centre is not None and tuple(centre.shape) != (H, W, 3):
        raise ValueError(f"centre must have shape {(H, W, 3)}; got {tuple(centre.shape)}")
    if points.ndim != 2 or points.shape[1] != 2:
        raise ValueError(f"points must have shape (N, 2); got {tuple(points.shape)}")


def soft_direction_maps(
    views: Float[ArrayLike, "n H W 3"],
    hparams: EndToEndParams,
    config: EndToEndConfig,
    *,
    direction: int = HORIZONTAL,
) -> tuple[Float[Array, "H W"], Float[Array, "H W"], Float[Array, "H W"]]:
    """Soft disparity, confidence and peak ratio of every centre-view pixel, one direction.

    `soft_filter_responses` (the pre-processing and bank of `soft_edge_maps`); then
    `soft_select`: ``p = softmax(r / τ)`` (see ``EndToEndConfig.temperature``),
    ``d = Σ p_i d_i``, ``c = Σ p_i r_i``; and the peak ratio ``ρ = c / mean_i r_i``. With
    ``temperature = "absolute"`` ``d, c`` equal `soft_edge_maps`.

    Args:
        views: ``(n, H, W, 3)`` RGB in [0, 1], the central row (``HORIZONTAL``) or column
            (``VERTICAL``) of views, ``n >= 3``.
        hparams: `EndToEndParams` (temperature, presmooth_sigma).
        config: `EndToEndConfig` with ``d_max`` set.
        direction: `HORIZONTAL` or `VERTICAL`.

    Returns:
        ``(disparity, confidence, peak)``, each ``(H, W)``.

    Raises:
        ValueError: on a bad shape or an unset ``config.d_max``.

    References:
        Thesis Alg. 1 (relaxed: softmax for argmax / max).
    """
    if config.d_max is None:
        raise ValueError("EndToEndConfig.d_max is None; set it (or use prepare_scene)")
    v = hparams.values()
    mag, disps = soft_filter_responses(
        views,
        d_max=float(config.d_max),
        n_filters=config.n_filters,
        presmooth_sigma=v["presmooth_sigma"],
        edge_shift=config.edge_shift,
        aa_sigma=config.aa_sigma,
        blur_radius=config.blur_radius,
        direction=direction,
    )
    tau = v["temperature"].astype(mag.dtype)
    if config.temperature == "relative":
        tau = tau * jnp.max(mag, axis=-1, keepdims=True)
    else:
        tau = tau[..., None]
    d, c = soft_select(mag, disps, tau)
    peak = c / jnp.mean(mag, axis=-1)
    return d, c, peak


def soft_point_labels(
    hparams: EndToEndParams,
    views_row: Float[ArrayLike, "V H W 3"],
    views_col: Float[ArrayLike, "U H W 3"],
    points: Float[ArrayLike, "N 2"],
    config: EndToEndConfig,
    *,
    direction: Int[ArrayLike, " N"] | None = None,
    valid: Bool[ArrayLike, " N"] | None = None,
) -> tuple[Float[Array, " N"], Float[Array, " N"]]:
    """Soft labels and log inverse label weights ``R`` of fixed edge points (steps 1–3).

    Args:
        hparams: `EndToEndParams`.
        views_row: ``(V, H, W, 3)`` central row of views, RGB in [0, 1].
        views_col: ``(U, H, W, 3)`` central column of views.
        points: ``(N, 2)`` ``(x, y)`` positions in the centre view.
        config: `EndToEndConfig` (``d_max`` must be set).
        direction: ``(N,)`` int EPI direction that detected each point (enables
            ``direction_bias``); ``None``: plain confidence mixing.
        valid: ``(N,)`` bool (default all); invalid points get label 0, ``R = 0`` and do not
            enter the geometric means.

    Returns:
        ``(label (N,), R (N,))``: mixed soft disparity and
        ``R = -γ_c log(c / c̄) - γ_ρ log(ρ / ρ̄)``.

    Raises:
        ValueError: on bad shapes or an unset ``config.d_max``.

    References:
        Thesis Alg. 1 (relaxed), Sec. 7.1.5 (``w = exp(-R)``).
    """
    views_row, views_col = jnp.asarray(views_row), jnp.asarray(views_col)
    dt = jnp.result_type(views_row, jnp.float32)
    points = jnp.asarray(points, dt)
    _check_inputs(views_row, views_col, points, None)
    N = points.shape[0]
    if valid is None:
        valid = jnp.ones((N,), bool)
    valid = jnp.asarray(valid, bool)
    if valid.shape != (N,):
        raise ValueError(f"valid must have shape ({N},); got {tuple(valid.shape)}")
    if direction is not None:
        direction = jnp.asarray(direction)
        if direction.shape != (N,):
            raise ValueError(f"direction must have shape ({N},); got {tuple(direction.shape)}")
    v = hparams.values()
    h_maps = soft_direction_maps(views_row, hparams, config, direction=HORIZONTAL)
    v_maps = soft_direction_maps(views_col, hparams, config, direction=VERTICAL)
    dh, ch, ph = (sample_bilinear(a, points) for a in h_maps)
    dv, cv, pv = (sample_bilinear(a, points) for a in v_maps)
    floor = jnp.asarray(config.confidence_floor, dt)
    lch, lcv = jnp.log(ch + floor), jnp.log(cv + floor)
    k = v["direction_power"].astype(dt)
    if direction is None:
        wh = jax.nn.sigmoid(k * (lch - lcv))
    else:
        sign = jnp.where(direction == HORIZONTAL, 1.0, -1.0).astype(dt)
        wh = jax.nn.sigmoid(sign * (k * (lch - lcv) + v["direction_bias"].astype(dt)))
    mix = lambda a, b: wh * a + (1.0 - wh) * b
    label = mix(dh, dv)
    logc = jnp.log(mix(ch, cv) + floor)
    logp = jnp.log(mix(ph, pv) + floor)
    mf = valid.astype(dt)
    count = jnp.maximum(jnp.sum(mf), 1.0)
    centred = lambda a: a - jnp.sum(a * mf) / count
    gamma_c, gamma_p = v["confidence_power"].astype(dt), v["peak_power"].astype(dt)
    R = -gamma_c * centred(logc) - gamma_p * centred(logp)
    return jnp.where(valid, label, 0.0), jnp.where(valid, R, 0.0)


def end_to_end_prediction(
    hparams: EndToEndParams,
    views_row: Float[ArrayLike, "V H W 3"],
    views_col: Float[ArrayLike, "U H W 3"],
    points: Float[ArrayLike, "N 2"],
    centre: Float[ArrayLike, "H W 3"],
    config: EndToEndConfig,
    *,
    direction: Int[ArrayLike, " N"] | None = None,
    valid: Bool[ArrayLike, " N"] | None = None,
) -> Prediction:
    """`end_to_end_disparity` returning the full `Prediction` (render maps, solve status)."""
    views_row, views_col = jnp.asarray(views_row), jnp.asarray(views_col)
    dt = jnp.result_type(views_row, jnp.float32)
    centre = jnp.asarray(centre, dt)
    points = jnp.asarray(points, dt)
    _check_inputs(views_row, views_col, points, centre)
    label, R = soft_point_labels(
        hparams, views_row, views_col, points, config, direction=direction, valid=valid
    )
    v = hparams.values()
    Q = v["q_scale"].astype(dt) * image_gradient_magnitude(centre)
    params = DiffParams(position=points, label=label, R=R, Q=Q)
    model = eqx.tree_at(
        lambda c: (c.label_weight, c.smoothness, c.q_scale),
        config.model,
        (v["label_weight"].astype(dt), v["smoothness"].astype(dt), v["q_scale"].astype(dt)),
    )
    return predict(params, model, valid=valid)


def end_to_end_disparity(
    hparams: EndToEndParams,
    views_row: Float[ArrayLike, "V H W 3"],
    views_col: Float[ArrayLike, "U H W 3"],
    points: Float[ArrayLike, "N 2"],
    centre: Float[ArrayLike, "H W 3"],
    config: EndToEndConfig,
    *,
    direction: Int[ArrayLike, " N"] | None = None,
    valid: Bool[ArrayLike, " N"] | None = None,
) -> Float[Array, "H W"]:
    """Dense centre disparity from the views, differentiable in every hyperparameter.

    Soft edge detection of both EPI directions → soft labels and weights of the fixed edge
    points (`soft_point_labels`) → `render` → eq 7.2 diffusion with smoothness
    ``smoothness · exp(-q_scale |∇I|)`` and data weight ``label_weight · λ^Z`` (`predict`,
    custom-VJP `solve_poisson`). Pure and jit-able (``config``'s static fields and the
    shapes are static); reverse-mode differentiable w.r.t. ``hparams`` and the views (not
    the point positions, which only move the samples).

    Args:
        hparams: `EndToEndParams`.
        views_row: ``(V, H, W, 3)`` central row of views, RGB in [0, 1].
        views_col: ``(U, H, W, 3)`` central column of views.
        points: ``(N, 2)`` fixed ``(x, y)`` edge positions (e.g. from `detect_edges`).
        centre: ``(H, W, 3)`` centre view (|∇I| of the smoothness term).
        config: `EndToEndConfig` with ``d_max`` set.
        direction: optional ``(N,)`` int EPI direction of each point (see
            `soft_point_labels`).
        valid: ``(N,)`` bool point mask (default all).

    Returns:
        ``(H, W)`` disparity, pixels per view step.

    Raises:
        ValueError: on mismatched shapes or an unset ``config.d_max``.

    References:
        Thesis Alg. 1 (relaxed), eqs 7.2–7.14, Sec. 7.1.5, Sec. 7.2.3; SPEC §1, §5, §6.
    """
    return end_to_end_prediction(
        hparams,
        views_row,
        views_col,
        points,
        centre,
        config,
        direction=direction,
        valid=valid,
    ).disparity


def _with_d_max(config: EndToEndConfig, d_max: float) -> EndToEndConfig:
    return config if config.d_max == d_max else dataclasses.replace(config, d_max=float(d_max))


def prepare_scene(
    lf: LightField,
    *,
    edge_config: EdgeConfig = EdgeConfig(),
    key=None,
) -> EndToEndScene:
    """Fix the edge positions of a light field (hard `detect_edges`) and bundle its arrays.

    Only valid points are kept (compacted: the detector's fixed capacity of ``2 H W`` slots
    is mostly empty, and the render's cost grows with the number of slots).

    Args:
        lf: the light field (central cross-hair; centre GT, if any, becomes the target).
        edge_config: `EdgeConfig` of the hard detection; its ``d_max`` rule also sets the
            soft detector's half-range.
        key: PRNG key for `detect_edges`.

    Returns:
        `EndToEndScene`.

    Raises:
        ValueError: as `detect_edges`; if no edge point is found.
    """
    edges = detect_edges(lf, edge_config, key=key)
    keep = np.asarray(edges.valid)
    pts = np.stack([np.asarray(edges.x), np.asarray(edges.y)], 1)[keep]
    if pts.shape[0] == 0:
        raise ValueError(f"detect_edges found no edge points in {lf.name!r}")
    row, col = lf.cross_hair()
    return EndToEndScene(
        views_row=jnp.asarray(row),
        views_col=jnp.asarray(col),
        centre=jnp.asarray(lf.centre_view),
        points=jnp.asarray(pts, jnp.float32),
        direction=jnp.asarray(np.asarray(edges.direction)[keep], jnp.int32),
        valid=jnp.ones(pts.shape[0], bool),
        hard_label=jnp.asarray(np.asarray(edges.disparity)[keep], jnp.float32),
        target=None if lf.centre_gt is None else jnp.asarray(lf.centre_gt),
        target_mask=None if lf.centre_gt_mask is None else jnp.asarray(lf.centre_gt_mask),
        d_max=float(resolve_d_max(edge_config, lf.disparity_range)),
    )


def _scene_prediction(hparams, scene: EndToEndScene, config: EndToEndConfig) -> Prediction:
    return end_to_end_prediction(
        hparams,
        scene.views_row,
        scene.views_col,
        scene.points,
        scene.centre,
        _with_d_max(config, scene.d_max),
        direction=scene.direction,
        valid=scene.valid,
    )


def end_to_end_loss(
    hparams: EndToEndParams, scene: EndToEndScene, config: EndToEndConfig
) -> tuple[Float[Array, ""], Prediction]:
    """Supervised loss (``config.loss``: mean L1 or mean squared error over the valid
    ground-truth pixels) of the end-to-end prediction on a scene.

    Returns:
        ``(loss, prediction)``.

    Raises:
        ValueError: if the scene has no target disparity.

    References:
        Thesis Sec. 7.2.3 (supervised L1).
    """
    if scene.target is None:
        raise ValueError("the scene has no target (ground-truth) disparity")
    pred = _scene_prediction(hparams, scene, config)
    d = pred.disparity
    target = scene.target.astype(d.dtype)
    if config.loss == "l1":
        return supervised_loss(d, target, scene.target_mask), pred
    err = (d - target) ** 2
    if scene.target_mask is None:
        return jnp.mean(err), pred
    m = scene.target_mask.astype(d.dtype)
    return jnp.sum(err * m) / jnp.maximum(jnp.sum(m), 1.0), pred


_DEFAULT_CONFIG = EndToEndConfig()


@eqx.filter_jit
def end_to_end_value_and_grad(
    hparams: EndToEndParams, scene: EndToEndScene, config: EndToEndConfig = _DEFAULT_CONFIG
) -> tuple[Float[Array, ""], EndToEndParams, Float[Array, "H W"], dict[str, Array]]:
    """Supervised loss, its gradient w.r.t. every hyperparameter, and the prediction (jitted).

    One forward pass (soft detector, render, solve) and one backward pass (adjoint solve,
    render and detector VJPs). `tune` takes its steps with this function.

    Args:
        hparams: `EndToEndParams`.
        scene: `EndToEndScene` with a target.
        config: `EndToEndConfig` (``d_max`` taken from the scene).

    Returns:
        ``(loss, grads, disparity, info)``: the scalar loss, an `EndToEndParams` of
        gradients (w.r.t. the stored, i.e. log-parametrised, leaves), the ``(H, W)``
        prediction and ``info`` with the solve's ``solver_iterations``,
        ``solver_residual`` and the render's tile ``overflow``.

    Raises:
        ValueError: if the scene has no target.
    """
    (loss, pred), g = eqx.filter_value_and_grad(end_to_end_loss, has_aux=True)(
        hparams, scene, config
    )
    info = {
        "solver_iterations": pred.solve.iterations,
        "solver_residual": pred.solve.residual,
        "overflow": pred.rendered.overflow,
    }
    return loss, g, pred.disparity, info


_scene_prediction_jit = eqx.filter_jit(_scene_prediction)


def evaluate_scene(
    hparams: EndToEndParams, scene: EndToEndScene, config: EndToEndConfig = _DEFAULT_CONFIG
) -> Float[Array, "H W"]:
    """The end-to-end centre disparity of a prepared scene (jitted `end_to_end_disparity`).

    Args:
        hparams: `EndToEndParams`.
        scene: `EndToEndScene` (no target needed).
        config: `EndToEndConfig` (``d_max`` taken from the scene).

    Returns:
        ``(H, W)`` disparity, pixels per view step.
    """
    return _scene_prediction_jit(hparams, scene, config).disparity


def tune(
    hparams0: EndToEndParams,
    train_scene: EndToEndScene,
    steps: int,
    lr: float,
    *,
    config: EndToEndConfig = _DEFAULT_CONFIG,
    callback: Callable[[int, dict], None] | None = None,
) -> tuple[EndToEndParams, dict[str, np.ndarray]]:
    """Tune the hyperparameters by Adam on the supervised loss of one scene.

    Each step is one jitted forward + backward pass through the whole pipeline (soft
    detector, render, solve and its adjoint solve). A step whose loss or gradient is not
    finite is skipped (hyperparameters unchanged; ``history["skipped"]``).

    Args:
        hparams0: initial `EndToEndParams`.
        train_scene: `EndToEndScene` with a target disparity (`prepare_scene`).
        steps: Adam steps (>= 0).
        lr: Adam learning rate; on the log-parametrised values a step of ``lr`` is a
            relative change of about ``lr``.
        config: `EndToEndConfig` (its ``d_max`` is replaced by the scene's).
        callback: called as ``callback(step, record)`` after every step (``record``: the
            per-step values listed below, as floats).

    Returns:
        ``(hparams, history)``: the final hyperparameters and per-step NumPy arrays
        ``loss`` (at the step's starting hyperparameters), ``grad_norm``, ``seconds``,
        ``skipped``, ``solver_iterations``, ``solver_residual``, ``overflow`` and one array
        per name of `HPARAM_NAMES` (values at the step's start); plus ``final_loss`` (loss
        of the returned hyperparameters) and ``disparity`` (their ``(H, W)`` map).

    Raises:
        ValueError: on ``steps < 0``, ``lr <= 0`` or a scene without a target.

    References:
        Thesis Sec. 7.2.3 (supervised loss); Kingma & Ba, "Adam", ICLR 2015.
    """
    if not (isinstance(steps, int) and steps >= 0):
        raise ValueError(f"steps must be an int >= 0; got {steps!r}")
    if not (math.isfinite(lr) and lr > 0):
        raise ValueError(f"lr must be finite and > 0; got {lr}")
    if train_scene.target is None:
        raise ValueError("the training scene has no target (ground-truth) disparity")
    opt = optax.adam(lr)
    state = opt.init(hparams0)
    hp = hparams0
    keys = (
        "loss",
        "grad_norm",
        "seconds",
        "skipped",
        "solver_iterations",
        "solver_residual",
        "overflow",
    )
    hist: dict[str, list] = {k: [] for k in keys + HPARAM_NAMES}
    for step in range(steps):
        t0 = time.perf_counter()
        loss, g, _, info = end_to_end_value_and_grad(hp, train_scene, config)
        gnorm = float(optax.tree.norm(g))
        ok = math.isfinite(float(loss)) and math.isfinite(gnorm)
        record = {n: float(x) for n, x in hp.values().items()}
        if ok:
            upd, state = opt.update(g, state, hp)
            hp = optax.apply_updates(hp, upd)
        record.update(
            loss=float(loss),
            grad_norm=gnorm,
            seconds=time.perf_counter() - t0,
            skipped=float(not ok),
            **{k: float(x) for k, x in info.items()},
        )
        for k in hist:
            hist[k].append(record[k])
        if callback is not None:
            callback(step, record)
    loss, _, disp, _ = end_to_end_value_and_grad(hp, train_scene, config)
    history = {k: np.asarray(v) for k, v in hist.items()}
    history["final_loss"] = np.asarray(float(loss))
    history["disparity"] = np.asarray(disp)
    return hp, history


__all__ = [
    "HPARAM_NAMES",
    "POSITIVE_HPARAMS",
    "REAL_HPARAMS",
    "EndToEndConfig",
    "EndToEndParams",
    "EndToEndScene",
    "end_to_end_disparity",
    "end_to_end_loss",
    "end_to_end_prediction",
    "end_to_end_value_and_grad",
    "evaluate_scene",
    "prepare_scene",
    "soft_direction_maps",
    "soft_point_labels",
    "tune",
]
