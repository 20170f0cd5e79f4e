"""Per-point splatting kernels at sub-pixel positions (thesis eqs 7.4 and 7.6).

Pixel centres sit at integer coordinates ``(x, y)`` (x = column, y = row). A point at sub-pixel
position ``(x_p, y_p)`` covers the ``(2r+1)×(2r+1)`` pixels around ``round(x_p), round(y_p)``,
i.e. exactly the pixels with ``|x - x_p| < r + 1/2`` and ``|y - y_p| < r + 1/2``.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from ._config import RenderConfig

_DEFAULT_RENDER = RenderConfig()


def label_kernel_1d(d: ArrayLike, sigma: ArrayLike, radius: int) -> Array:
    """One axis of the depth-label Gaussian (eq 7.4), truncated continuously to the support.

    ``g(d) = max(exp(-d²/2σ²) - e, 0) / (1 - e)`` with ``e = exp(-(r+½)²/2σ²)``: a Gaussian of
    peak 1 that reaches exactly zero at the edge of the ``2r+1`` support, so that a pixel
    leaving the support as the point moves carries no weight (the splat is continuous in the
    position). The 2-D kernel is the product of the two axes (an isotropic Gaussian before
    truncation).

    Args:
        d: offsets in pixels, any shape.
        sigma: σ_S in pixels.
        radius: r, half-size of the support in pixels.

    Returns:
        Kernel values in [0, 1], same shape as ``d``.

    References:
        Thesis eq 7.4 (σ_S = 1.3, 7×7 support, Sec. 7.1.5).
    """
    d = jnp.asarray(d)
    inv = 1.0 / (2.0 * jnp.asarray(sigma, d.dtype) ** 2)
    edge = jnp.exp(-((radius + 0.5) ** 2) * inv)
    return jnp.maximum(jnp.exp(-(d * d) * inv) - edge, 0.0) / (1.0 - edge)


def weight_kernel(r2: ArrayLike, sigma: ArrayLike, order: int) -> Array:
    """The super-Gaussian label-weight profile ``exp(-(r²/2σ_λ²)^p)`` (eq 7.6, without w).

    Args:
        r2: squared distances in pixels², any shape, >= 0.
        sigma: σ_λ in pixels.
        order: p >= 1, integer.

    Returns:
        Values in (0, 1], same shape as ``r2``.

    References:
        Thesis eq 7.6 (p = 2, σ_λ = 0.71, Sec. 7.1.5).
    """
    r2 = jnp.asarray(r2)
    u = r2 / (2.0 * jnp.asarray(sigma, r2.dtype) ** 2)
    return jnp.exp(-(u**order))


class SplatResult(eqx.Module):
    """Additive (occlusion-free) splat of a point set.

    Attributes:
        label_sum: ``(H, W)`` Σ_x S_x^Z = Σ_x Z_x g_x (eq 7.4 summed without α).
        density: ``(H, W)`` Σ_x g_x, the summed normalised Gaussian in xy.
        weight: ``(H, W)`` Σ_x λ_x^Z, the summed super-Gaussian label weights (eq 7.6).
    """

    label_sum: Float[Array, "H W"]
    density: Float[Array, "H W"]
    weight: Float[Array, "H W"]

    @property
    def label(self) -> Float[Array, "H W"]:
        """Density-normalised label ``label_sum / density`` (0 where nothing was splatted)."""
        den = self.density
        return jnp.where(den > 0, self.label_sum / jnp.where(den > 0, den, 1.0), 0.0)


def check_points(position, label, log_weight, valid) -> None:
    """Shape checks shared by the renderers (trace time).

    Raises:
        ValueError: quoting the actual shapes.
    """
    if position.ndim != 2 or position.shape[-1] != 2:
        raise ValueError(f"position must have shape (N, 2) as (x, y); got {tuple(position.shape)}")
    n = position.shape[0]
    for name, a in (("label", label), ("log_weight", log_weight)):
        if tuple(a.shape) != (n,):
            raise ValueError(
                f"{name} must have shape ({n},) to match position; got {tuple(a.shape)}"
            )
    if valid is not None and tuple(valid.shape) != (n,):
        raise ValueError(
            f"valid must have shape ({n},) to match position; got {tuple(valid.shape)}"
        )


def check_shape(shape) -> tuple[int, int]:
    try:
        H, W = (int(s) for s in shape)
    except Exception as err:
        raise ValueError(f"shape must be (H, W); got {shape!r}") from err
    if H < 1 or W < 1:
        raise ValueError(f"shape must be positive (H, W); got {shape!r}")
    return H, W


def footprint(position: Float[Array, "N 2"], radius: int):
    """Integer pixel coordinates of each point's square support.

    Returns:
        ``(px, py)``: ``(N, 2r+1)`` int32 columns and rows (may lie outside the image).
    """
    offs = jnp.arange(-radius, radius + 1, dtype=jnp.int32)
    c = jnp.round(jax.lax.stop_gradient(position)).astype(jnp.int32)
    return c[:, 0:1] + offs[None], c[:, 1:2] + offs[None]


def splat(
    position: Float[ArrayLike, "N 2"],
    label: Float[ArrayLike, " N"],
    log_weight: Float[ArrayLike, " N"],
    shape: tuple[int, int],
    config: RenderConfig = _DEFAULT_RENDER,
    *,
    valid: Bool[ArrayLike, " N"] | None = None,
) -> SplatResult:
    """Splat points additively (no occlusion): Gaussian labels and super-Gaussian weights.

    Every point adds ``Z g(x - x_p) g(y - y_p)`` to ``label_sum``, ``g g`` to ``density`` and
    ``exp(-R) exp(-(r²/2σ_λ²)^p)`` to ``weight`` on its ``(2r+1)²`` support (a scatter-add;
    no loops over points). Differentiable in ``position``, ``label`` and ``log_weight``.
    Pixels outside the image are dropped.

    Args:
        position: ``(N, 2)`` sub-pixel ``(x, y)`` = (column, row), pixel centres at integers.
        label: ``(N,)`` depth label Z of each point (disparity or depth).
        log_weight: ``(N,)`` R; the label weight scale is ``w = exp(-R)`` (Sec. 7.1.5).
        shape: ``(H, W)`` of the output.
        config: kernel sizes (`RenderConfig`).
        valid: ``(N,)`` bool; invalid points contribute nothing. Default: all valid.

    Returns:
        A `SplatResult` of ``(H, W)`` maps in the dtype of ``position``.

    Raises:
        ValueError: on mismatched shapes.

    References:
        Thesis eqs 7.4, 7.6; Fig. 7.3 (points must not vanish at sub-pixel positions).
    """
    position = jnp.asarray(position)
    label = jnp.asarray(label, position.dtype)
    log_weight = jnp.asarray(log_weight, position.dtype)
    valid = None if valid is None else jnp.asarray(valid, bool)
    check_points(position, label, log_weight, valid)
    H, W = check_shape(shape)
    r = config.radius
    px, py = footprint(position, r)  # (N, K)
    dx = px.astype(position.dtype) - position[:, 0:1]
    dy = py.astype(position.dtype) - position[:, 1:2]
    gx = label_kernel_1d(dx, config.sigma_label, r)
    gy = label_kernel_1d(dy, config.sigma_label, r)
    g = gy[:, :, None] * gx[:, None, :]  # (N, K, K) rows × columns
    r2 = dy[:, :, None] ** 2 + dx[:, None, :] ** 2
    sg = weight_kernel(r2, config.sigma_weight, config.weight_order)
    sg = sg * jnp.exp(-log_weight)[:, None, None]
    ok = jnp.ones(label.shape, bool) if valid is None else valid
    ok = ok[:, None, None] & (py[:, :, None] >= 0) & (py[:, :, None] < H)
    ok = ok & (px[:, None, :] >= 0) & (px[:, None, :] < W)
    rows = jnp.where(ok, py[:, :, None], H)  # out of range → dropped
    cols = jnp.where(ok, px[:, None, :], W)
    rows = jnp.broadcast_to(rows, g.shape)
    cols = jnp.broadcast_to(cols, g.shape)

    def scatter(v):
        return jnp.zeros((H, W), position.dtype).at[rows, cols].add(v, mode="drop")

    return SplatResult(
        label_sum=scatter(g * label[:, None, None]), density=scatter(g), weight=scatter(sg)
    )
