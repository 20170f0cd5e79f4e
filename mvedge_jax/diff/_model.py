"""The differentiable model: points → render (eqs 7.3–7.14) → diffusion (eq 7.2) → disparity."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from .._fields import check_fields, hyperparameter
from .._image import as_float_image
from .._pad import edge_pad
from ..solve import SolverConfig, SolveResult, solve_poisson
from ._composite import RenderResult, render
from ._config import RenderConfig


class ModelConfig(eqx.Module):
    """Rendering and diffusion of the differentiable edge model.

    Attributes:
        render: `RenderConfig` of the splatting and compositing.
        label_weight: global factor on the rendered label weight λ^Z (the data term of eq 7.2);
            per point the weight is ``label_weight * exp(-R)``. Large against the smoothness
            (cf. ω = 150 of eq 6.3) so that the diffusion interpolates the labels rather than
            smoothing them; a factor 10 left MSE×100 ~10–40× higher in the completeness runs.
        smoothness: global factor on the smoothness ϑ = exp(-Q) of eq 7.2.
        q_scale: ``Q`` is initialised to ``q_scale * |∇I|`` (Sec. 7.1.5 uses |∇I|; the scale
            sets how strongly image edges stop the diffusion, I in [0, 1]).
        solver: `SolverConfig` of the differentiable Poisson solve.
    """

    render: RenderConfig = RenderConfig()
    label_weight: Array = hyperparameter(100.0, differentiable=True, lower=0.0, lower_open=True)
    smoothness: Array = hyperparameter(1.0, differentiable=True, lower=0.0, lower_open=True)
    q_scale: Array = hyperparameter(10.0, differentiable=True)
    solver: SolverConfig = SolverConfig()

    def __check_init__(self):
        check_fields(self)


_DEFAULT_MODEL = ModelConfig()


class DiffParams(eqx.Module):
    """The optimised parameters Θ̄ = {Z_x, K_x, R, Q} (Sec. 7.1.5).

    Attributes:
        position: ``(N, 2)`` float, image-space position ``(x, y)`` of each point (K x).
        label: ``(N,)`` float, depth label Z of each point (disparity in pixels per view step
            for light fields).
        R: ``(N,)`` float, per-point log inverse label weight, ``w = exp(-R)`` (init 0).
        Q: ``(H, W)`` float, smoothness logits, ``ϑ = exp(-Q)`` (init ``|∇I|``).
    """

    position: Float[Array, "N 2"]
    label: Float[Array, " N"]
    R: Float[Array, " N"]
    Q: Float[Array, "H W"]

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)`` of the image the points live in."""
        return int(self.Q.shape[0]), int(self.Q.shape[1])


class Prediction(eqx.Module):
    """Output of `predict`.

    Attributes:
        disparity: ``(H, W)`` diffused label map D (eq 7.2).
        rendered: the `RenderResult` (S^Z, λ^Z, α, overflow) before the label-weight factor.
        solve: the `SolveResult` of the Poisson solve (iterations, residual).
    """

    disparity: Float[Array, "H W"]
    rendered: RenderResult
    solve: SolveResult


def image_gradient_magnitude(image: Float[ArrayLike, "H W *C"]) -> Float[Array, "H W"]:
    """``|∇I|`` per pixel: norm over channels of the central differences (edge-replicated).

    Args:
        image: ``(H, W)`` or ``(H, W, C)`` float image (e.g. RGB in [0, 1]).

    Returns:
        ``(H, W)`` gradient magnitude in image units per pixel.

    Raises:
        ValueError: if ``image`` is not 2-D or 3-D, or 3-D with no channel.
    """
    image = as_float_image(image, "image")
    im = image if image.ndim == 3 else image[..., None]
    p = edge_pad(im, ((1, 1), (1, 1), (0, 0)))
    gx = 0.5 * (p[1:-1, 2:] - p[1:-1, :-2])
    gy = 0.5 * (p[2:, 1:-1] - p[:-2, 1:-1])
    return jnp.sqrt(jnp.sum(gx * gx + gy * gy, axis=-1))


def initial_q(image: Float[ArrayLike, "H W *C"], config: ModelConfig = _DEFAULT_MODEL) -> Array:
    """``Q = q_scale · |∇I|`` (Sec. 7.1.5: Q initialised to the image-gradient magnitude).

    Args:
        image: ``(H, W)`` or ``(H, W, C)`` float image in [0, 1].
        config: `ModelConfig` (``q_scale``).

    Returns:
        ``(H, W)`` Q.
    """
    g = image_gradient_magnitude(image)
    return jnp.asarray(config.q_scale, g.dtype) * g


def smoothness_weights(
    Q: Float[ArrayLike, "H W"], smoothness: Float[ArrayLike, ""] = 1.0
) -> tuple[Float[Array, "H W-1"], Float[Array, "H-1 W"]]:
    """Edge weights of eq 7.2 from per-pixel ϑ = exp(-Q): the mean ϑ of the two pixels.

    Args:
        Q: ``(H, W)`` smoothness logits.
        smoothness: global factor.

    Returns:
        ``(weight_x (H, W-1), weight_y (H-1, W))`` for `solve_poisson`.
    """
    Q = jnp.asarray(Q)
    if Q.ndim != 2:
        raise ValueError(f"Q must have shape (H, W); got {tuple(Q.shape)}")
    t = jnp.exp(-Q) * jnp.asarray(smoothness, Q.dtype)
    return 0.5 * (t[:, 1:] + t[:, :-1]), 0.5 * (t[1:, :] + t[:-1, :])


def initial_params(
    position: Float[ArrayLike, "N 2"],
    label: Float[ArrayLike, " N"],
    image: Float[ArrayLike, "H W *C"],
    config: ModelConfig = _DEFAULT_MODEL,
) -> DiffParams:
    """Initial parameters: the given points, ``R = 0``, ``Q = q_scale · |∇I|``.

    Args:
        position: ``(N, 2)`` ``(x, y)`` pixel positions.
        label: ``(N,)`` labels (disparity).
        image: ``(H, W, 3)`` reference view in [0, 1] (defines the grid and Q).
        config: `ModelConfig`.

    Returns:
        `DiffParams` in float32 (or the float dtype of ``position``).

    Raises:
        ValueError: on mismatched shapes.
    """
    position = jnp.asarray(position)
    dtype = position.dtype if jnp.issubdtype(position.dtype, jnp.floating) else jnp.float32
    position = position.astype(dtype)
    label = jnp.asarray(label, dtype)
    if position.ndim != 2 or position.shape[1] != 2:
        raise ValueError(f"position must have shape (N, 2); got {tuple(position.shape)}")
    if label.shape != (position.shape[0],):
        raise ValueError(f"label must have shape ({position.shape[0]},); got {tuple(label.shape)}")
    Q = initial_q(jnp.asarray(image, dtype), config)
    return DiffParams(position=position, label=label, R=jnp.zeros_like(label), Q=Q)


def predict(
    params: DiffParams,
    config: ModelConfig = _DEFAULT_MODEL,
    *,
    valid: Bool[ArrayLike, " N"] | None = None,
    x0: Float[ArrayLike, "H W"] | None = None,
    prior: Float[ArrayLike, "H W"] | None = None,
) -> Prediction:
    """Render the points and diffuse them into a dense label map (eq 7.2).

    ``D = argmin Σ λ (D - S)² + Σ_edges ϑ (D_p - D_q)²`` with ``S, λ`` from `render`
    (λ scaled by ``label_weight``) and ``ϑ`` from `smoothness_weights`, solved by the
    differentiable `solve_poisson` (gradients by one adjoint solve). jit-able.

    With a ``prior`` map ``P`` (not in the thesis), the points' departures from the prior are
    diffused instead: each point carries ``r_x = Z_x - P(x)`` (``P`` sampled bilinearly at
    its position), the departures are splatted with the same weights and occlusions as the
    labels (`render`'s ``value``) into ``S_r``, and
    ``D = P + argmin Σ λ (X - S_r)² + Σ_edges ϑ (X_p - X_q)²``. The smoothness then
    penalises the gradient of ``D - P`` rather than of ``D``, so a slanted surface known to
    the prior keeps its slope between sparse labels (plain diffusion flattens a steep ramp
    whose labels are weak against the smoothness), and labels equal to the prior under them
    reproduce it exactly: a splat that reaches across a depth edge of ``P`` carries its
    point's departure, not the jump of ``P`` (splatting the labels and subtracting ``P`` per
    pixel put the foreground's labels on the background beside every silhouette, a halo
    that the diffusion spread over textureless background: antinous BadPix(0.07) 16.3 →
    21.8 before any optimisation step; session 8). Used to refine a dense map (the Ch. 6
    result) rather than to rebuild it from the points. ``Prediction.rendered.label`` is then
    ``P + S_r``.

    Args:
        params: `DiffParams` (position, label, R, Q).
        config: `ModelConfig`.
        valid: ``(N,)`` bool mask of the points (default all).
        x0: optional warm start of the solve, a disparity map (no gradient flows through it).
        prior: optional ``(H, W)`` disparity map ``P`` (no gradient flows into it).

    Returns:
        `Prediction` with the ``(H, W)`` disparity, the rendered maps and the solve status.

    Raises:
        ValueError: if ``prior`` does not have the shape ``(H, W)`` of ``params.Q``.

    References:
        Thesis eqs 7.1–7.2, Sec. 7.1.5 (ϑ = exp(-Q), w = exp(-R)).
    """
    shape = params.shape
    departure = None
    if prior is not None:
        prior = jnp.asarray(prior, params.label.dtype)
        if prior.shape != shape:
            raise ValueError(f"prior must have shape {shape}; got {tuple(prior.shape)}")
        prior = jax.lax.stop_gradient(prior)
        # each point's departure from the prior under it: a splat that reaches across a
        # depth edge carries the point's departure, not the jump of the prior
        departure = params.label - sample_bilinear(prior, params.position)
    rendered = render(
        params.position,
        params.label,
        params.R,
        shape,
        config.render,
        valid=valid,
        value=departure,
    )
    wx, wy = smoothness_weights(params.Q, config.smoothness)
    lam = rendered.weight * jnp.asarray(config.label_weight, rendered.weight.dtype)
    if prior is None:
        sol = solve_poisson(lam, rendered.label, wx, wy, x0=x0, config=config.solver)
        return Prediction(disparity=sol.x, rendered=rendered, solve=sol)
    r0 = None if x0 is None else jnp.asarray(x0, lam.dtype) - prior
    sol = solve_poisson(lam, rendered.label, wx, wy, x0=r0, config=config.solver)
    rendered = eqx.tree_at(lambda r: r.label, rendered, rendered.label + prior)
    return Prediction(disparity=prior + sol.x, rendered=rendered, solve=sol)


def sample_bilinear(image: Float[ArrayLike, "H W"], position: Float[ArrayLike, "N 2"]) -> Array:
    """Bilinear samples of a map at sub-pixel ``(x, y)`` positions (border-clamped).

    Args:
        image: ``(H, W)`` map.
        position: ``(N, 2)`` ``(x, y)``.

    Returns:
        ``(N,)`` samples.
    """
    image = jnp.asarray(image)
    position = jnp.asarray(position, image.dtype)
    H, W = image.shape
    x = jnp.clip(position[:, 0], 0, W - 1)
    y = jnp.clip(position[:, 1], 0, H - 1)
    x0 = jnp.clip(jnp.floor(x), 0, max(W - 2, 0))
    y0 = jnp.clip(jnp.floor(y), 0, max(H - 2, 0))
    fx, fy = x - x0, y - y0
    xi, yi = x0.astype(jnp.int32), y0.astype(jnp.int32)
    x1, y1 = jnp.minimum(xi + 1, W - 1), jnp.minimum(yi + 1, H - 1)
    top = image[yi, xi] * (1 - fx) + image[yi, x1] * fx
    bot = image[y1, xi] * (1 - fx) + image[y1, x1] * fx
    return top * (1 - fy) + bot * fy


__all__ = [
    "DiffParams",
    "ModelConfig",
    "Prediction",
    "image_gradient_magnitude",
    "initial_params",
    "initial_q",
    "predict",
    "sample_bilinear",
    "smoothness_weights",
]
