"""Losses of the differentiable edge model (thesis eqs 7.15–7.16, Sec. 7.2.3)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from .._fields import check_fields, hyperparameter
from ..lightfield import backward_warp, forward_project_views, ssim_dissimilarity


class LossConfig(eqx.Module):
    """Weights of the self-supervised loss of eq 7.16 and of the supervised loss.

    ``L = mean(E) + ssim · mean(E_SSIM) + smooth · E_S - gradient_reward · mean(|∇E|)``
    (+ ``supervised · mean|D - D*|`` when a target disparity is given).

    Attributes:
        photometric: weight of the masked L1 warping error E (eq 7.15).
        ssim: weight of the SSIM dissimilarity ``(1 - SSIM) / 2`` of the warped views
            (3×3 windows), masked like E; minimising it rewards similarity.
        smooth: weight of the edge-aware smoothness ``E_S = mean(|∂D| exp(-edge_sharpness |∂I|))``.
        gradient_reward: weight of the reward for high gradients of the error map (eq 7.16,
            ``-∇E``; lets sharp depth edges keep the error they cause, Fig. 7.6).
        supervised: weight of the L1 error against a target disparity (Sec. 7.2.3).
        edge_sharpness: γ of the edge-aware smoothness (image in [0, 1]).
        occlusion_tolerance: a centre pixel is visible in a view when its disparity is at most
            this much below the z-buffer of the view at its landing position (label units).
        eps: ε of eq 7.15.
    """

    photometric: Array = hyperparameter(1.0, differentiable=True, lower=0.0)
    ssim: Array = hyperparameter(0.5, differentiable=True, lower=0.0)
    smooth: Array = hyperparameter(0.05, differentiable=True, lower=0.0)
    gradient_reward: Array = hyperparameter(0.05, differentiable=True, lower=0.0)
    supervised: Array = hyperparameter(1.0, differentiable=True, lower=0.0)
    edge_sharpness: Array = hyperparameter(10.0, differentiable=True, lower=0.0)
    occlusion_tolerance: Array = hyperparameter(
        0.25, differentiable=False, lower=0.0, lower_open=True
    )
    eps: Array = hyperparameter(1e-3, differentiable=True, lower=0.0, lower_open=True)

    def __check_init__(self):
        check_fields(self)


_DEFAULT_LOSS = LossConfig()


def _check_views(disparity, centre, others, offsets):
    if disparity.ndim != 2:
        raise ValueError(f"disparity must have shape (H, W); got {tuple(disparity.shape)}")
    H, W = disparity.shape
    if centre.shape != (H, W, 3):
        raise ValueError(f"centre view must have shape {(H, W, 3)}; got {tuple(centre.shape)}")
    if others.ndim != 4 or others.shape[1:] != (H, W, 3):
        raise ValueError(f"other views must have shape (K, {H}, {W}, 3); got {tuple(others.shape)}")
    if offsets.shape != (others.shape[0], 2):
        raise ValueError(
            f"offsets must have shape ({others.shape[0]}, 2) as (dr, dc); "
            f"got {tuple(offsets.shape)}"
        )


def occlusion_mask(
    disparity: Float[ArrayLike, "H W"],
    offset: Float[ArrayLike, 2],
    *,
    tolerance: Float[ArrayLike, ""] = 0.25,
) -> Bool[Array, "H W"]:
    """Which centre pixels are seen in the view at ``offset`` (no gradient; eq 7.15 ``M^i``).

    The centre disparity is forward-projected into the view with a z-buffer (the nearest
    point wins); a centre pixel is visible when its own disparity is within ``tolerance`` of
    the z-buffer sampled at its landing position ``(x - dc d, y - dr d)``, and that position
    lies inside the view. Holes of the z-buffer count as visible.

    Args:
        disparity: ``(H, W)`` centre disparity.
        offset: ``(2,)`` ``(dr, dc)`` of the view.
        tolerance: visibility slack in disparity units.

    Returns:
        ``(H, W)`` bool mask.

    References:
        Thesis eq 7.15 (binary occlusion mask recomputed at every iteration).
    """
    d = jnp.asarray(disparity)
    return _occlusion_masks(d, jnp.asarray(offset, d.dtype)[None], tolerance)[0]


def _occlusion_masks(d: Array, offsets: Array, tolerance) -> Array:
    """`occlusion_mask` for ``K`` offsets ``(K, 2)`` at once: ``(K, H, W)``. One stacked
    z-buffer (`forward_project_views`), so the program holds no batched scatter."""
    d = jax.lax.stop_gradient(d)
    H, W = d.shape
    proj, ok = forward_project_views(d, offsets)
    zb = jnp.where(ok, proj, -1e4)

    def visible(zb_k, offset):
        # nearest-pixel lookup of the z-buffer at the landing position
        ys, xs = jnp.meshgrid(
            jnp.arange(H, dtype=d.dtype), jnp.arange(W, dtype=d.dtype), indexing="ij"
        )
        lx = xs - offset[1] * d
        ly = ys - offset[0] * d
        inside = (lx > -0.5) & (lx < W - 0.5) & (ly > -0.5) & (ly < H - 0.5)
        xi = jnp.clip(jnp.floor(lx + 0.5), 0, W - 1).astype(jnp.int32)
        yi = jnp.clip(jnp.floor(ly + 0.5), 0, H - 1).astype(jnp.int32)
        return inside & (d >= zb_k[yi, xi] - jnp.asarray(tolerance, d.dtype))

    return jax.vmap(visible)(zb, offsets)


def _grad_abs(e: Array) -> Array:
    """Mean absolute forward difference of a map (both axes)."""
    return jnp.mean(jnp.abs(e[:, 1:] - e[:, :-1])) + jnp.mean(jnp.abs(e[1:, :] - e[:-1, :]))


def edge_aware_smoothness(
    disparity: Float[ArrayLike, "H W"], image: Float[ArrayLike, "H W C"], sharpness=10.0
) -> Array:
    """``mean(|∂x D| exp(-γ|∂x I|)) + mean(|∂y D| exp(-γ|∂y I|))`` (|∂I| = channel mean).

    References:
        Ranjan et al., "Competitive collaboration", CVPR 2019 (thesis ref. [79]).
    """
    d, im = jnp.asarray(disparity), jnp.asarray(image)
    gamma = jnp.asarray(sharpness, d.dtype)
    ix = jnp.mean(jnp.abs(im[:, 1:] - im[:, :-1]), axis=-1)
    iy = jnp.mean(jnp.abs(im[1:, :] - im[:-1, :]), axis=-1)
    sx = jnp.abs(d[:, 1:] - d[:, :-1]) * jnp.exp(-gamma * ix)
    sy = jnp.abs(d[1:, :] - d[:-1, :]) * jnp.exp(-gamma * iy)
    return jnp.mean(sx) + jnp.mean(sy)


def photometric_terms(
    disparity: Float[ArrayLike, "H W"],
    centre: Float[ArrayLike, "H W 3"],
    others: Float[ArrayLike, "K H W 3"],
    offsets: Float[ArrayLike, "K 2"],
    config: LossConfig = _DEFAULT_LOSS,
) -> dict[str, Array]:
    """The terms of eq 7.16 for a centre disparity and K other views.

    Every other view is warped onto the centre with `backward_warp` (``W[I^i](x, y) =
    I^i(x - dc d, y - dr d)``); per-view occlusion masks are recomputed from the current
    disparity (`occlusion_mask`, no gradient).

    Args:
        disparity: ``(H, W)`` centre disparity D.
        centre: ``(H, W, 3)`` centre view I in [0, 1].
        others: ``(K, H, W, 3)`` other views.
        offsets: ``(K, 2)`` their ``(dr, dc)`` from the centre view.
        config: `LossConfig`.

    Returns:
        Dict of scalars ``photometric`` (mean E, eq 7.15), ``ssim`` (masked mean of
        (1 - SSIM)/2), ``smooth`` (E_S), ``error_gradient`` (mean |∇E|), and the maps
        ``error`` ``(H, W)`` and ``mask_count`` ``(H, W)`` (views that see each pixel).

    Raises:
        ValueError: on mismatched shapes.

    References:
        Thesis eqs 7.15–7.16, Sec. 7.1.5 (∇E from the channel mean of E; E_S, E_SSIM in RGB).
    """
    d = jnp.asarray(disparity)
    centre, others = jnp.asarray(centre, d.dtype), jnp.asarray(others, d.dtype)
    offsets = jnp.asarray(offsets, d.dtype)
    _check_views(d, centre, others, offsets)

    masks = _occlusion_masks(d, offsets, config.occlusion_tolerance).astype(d.dtype)

    def per_view(view, off, m):
        return masked_view_errors(centre, backward_warp(view, d, off), m)

    return combine_view_errors(*jax.vmap(per_view)(others, offsets, masks), d, centre, config)


def masked_view_errors(
    reference: Float[Array, "H W 3"], warped: Float[Array, "H W 3"], mask: Float[Array, "H W"]
) -> tuple[Array, Array, Array]:
    """Per-pixel colour L1 and SSIM dissimilarity (channel means) of one warped view against
    the reference, times its visibility ``mask`` ``(H, W)``: ``(l1, dssim, mask)``."""
    l1 = jnp.mean(jnp.abs(reference - warped), axis=-1)
    dssim = jnp.mean(ssim_dissimilarity(reference, warped), axis=-1)
    return l1 * mask, dssim * mask, mask


def combine_view_errors(
    l1: Float[Array, "K H W"],
    dssim: Float[Array, "K H W"],
    mask: Float[Array, "K H W"],
    disparity: Float[Array, "H W"],
    reference: Float[Array, "H W 3"],
    config: LossConfig,
) -> dict[str, Array]:
    """The terms of eq 7.16 from the masked per-view errors of `masked_view_errors`: E is the
    mean over the views that see a pixel (eq 7.15); see `photometric_terms` for the keys."""
    count = jnp.sum(mask, axis=0)
    norm = 1.0 / (count + jnp.asarray(config.eps, disparity.dtype))
    error = jnp.sum(l1, axis=0) * norm
    e_ssim = jnp.sum(dssim, axis=0) * norm
    return {
        "photometric": jnp.mean(error),
        "ssim": jnp.mean(e_ssim),
        "smooth": edge_aware_smoothness(disparity, reference, config.edge_sharpness),
        "error_gradient": _grad_abs(error),
        "error": error,
        "mask_count": count,
    }


def weighted_terms(terms: dict[str, Array], config: LossConfig) -> Array:
    """Eq 7.16's weighted sum of `photometric_terms` (or `multiview_photometric_terms`):
    ``mean(E) + w_ssim E_SSIM + w_s E_S - w_g mean|∇E|``."""
    return (
        config.photometric * terms["photometric"]
        + config.ssim * terms["ssim"]
        + config.smooth * terms["smooth"]
        - config.gradient_reward * terms["error_gradient"]
    )


def self_supervised_loss(
    disparity: Float[ArrayLike, "H W"],
    centre: Float[ArrayLike, "H W 3"],
    others: Float[ArrayLike, "K H W 3"],
    offsets: Float[ArrayLike, "K 2"],
    config: LossConfig = _DEFAULT_LOSS,
) -> Array:
    """Eq 7.16: ``mean(E) + w_ssim E_SSIM + w_s E_S - w_g mean|∇E|`` (scalar).

    Args and references: see `photometric_terms`.
    """
    return weighted_terms(photometric_terms(disparity, centre, others, offsets, config), config)


def supervised_loss(
    disparity: Float[ArrayLike, "H W"],
    target: Float[ArrayLike, "H W"],
    mask: Bool[ArrayLike, "H W"] | None = None,
) -> Array:
    """Mean L1 error against a known disparity (thesis Sec. 7.2.3), over ``mask`` if given.

    Raises:
        ValueError: if the shapes differ.
    """
    d, t = jnp.asarray(disparity), jnp.asarray(target)
    if d.shape != t.shape:
        raise ValueError(f"target must have the disparity's shape {d.shape}; got {t.shape}")
    err = jnp.abs(d - t.astype(d.dtype))
    if mask is None:
        return jnp.mean(err)
    m = jnp.asarray(mask).astype(d.dtype)
    if m.shape != d.shape:
        raise ValueError(f"mask must have shape {d.shape}; got {m.shape}")
    return jnp.sum(err * m) / jnp.maximum(jnp.sum(m), 1.0)
