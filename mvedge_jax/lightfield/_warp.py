"""Warping between views of a light field by disparity (SPEC §0 sign convention).

Two directions:

* `backward_warp` — pull a source view into the target view's pixel grid using the target's
  disparity (bilinear, differentiable); `backward_warp_planar` for channels-first images.
* `forward_project` — push a source view's disparity map into another view's pixel grid
  (nearest pixel, z-buffered; used for reprojection, view consistency and tests);
  `forward_project_views` for many projections at once.
"""

from __future__ import annotations

import functools
import warnings

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from .._fields import check_lower_bound


class GpuCompileWarning(UserWarning):
    """A projection with the crack fill is compiled for a GPU, where XLA has been measured to
    compile the crack fill into wrong code (JAX 0.11.2 on an NVIDIA H200: wrong filled pixels
    in float64 and wrong gradients in float32 and float64; docs/RESULTS.md, "The crack fill
    compiles to wrong code"). Compare such results with the CPU before relying on them."""


def _default_platform() -> str:
    """The platform that jit-compiled code runs on by default: that of
    ``jax.config.jax_default_device`` when one is set, else JAX's default backend."""
    device = jax.config.jax_default_device
    if device is None:
        return jax.default_backend()
    return device if isinstance(device, str) else device.platform


def _warn_on_gpu() -> None:
    """Warn (`GpuCompileWarning`) when the crack fill is traced for a GPU."""
    if _default_platform() in ("gpu", "cuda", "rocm"):
        warnings.warn(
            "the crack fill of the z-buffered projection (forward_project, the cross-hair "
            "views of the reconstruction, view consistency) is compiled for a GPU, where XLA "
            "(JAX 0.11.2) has been measured to compile it into wrong code: wrong filled "
            "pixels in float64 and wrong gradients; compare with the CPU before relying on "
            "such results (docs/RESULTS.md, 'The crack fill compiles to wrong code')",
            GpuCompileWarning,
            stacklevel=2,
        )


def _check_offset(offset) -> tuple[Array, Array]:
    off = jnp.asarray(offset)
    if off.shape != (2,):
        raise ValueError(f"offset must be a pair (dr, dc) of shape (2,); got shape {off.shape}")
    return off[0], off[1]


def backward_warp(
    image: Float[ArrayLike, "H W *C"],
    disparity: Float[ArrayLike, "H W"],
    offset: ArrayLike,
) -> Float[Array, "H W *C"]:
    """Resample a view into a target view's pixel grid, given the target's disparity.

    ``out(x, y) = image(x - dc * d(x, y), y - dr * d(x, y))`` with bilinear interpolation and
    the sample position clamped to the image (border replication). With the ground-truth
    disparity of the target view, ``out ≈ target`` wherever the point is visible in both views
    (SPEC §0: ``centre(x, y) ≈ view[row, col](x - dc * d, y - dr * d)``).

    Differentiable in ``image`` and ``disparity`` (the gradient w.r.t. disparity is the
    bilinear image gradient along the epipolar direction; it is zero where the sample
    position is clamped). ``jit``- and ``vmap``-able; ``offset`` may be a traced array.

    Args:
        image: ``(H, W)`` or ``(H, W, C)`` float source view, located at angular offset
            ``offset = (dr, dc)`` (in view steps) from the target view.
        disparity: ``(H, W)`` float disparity of the TARGET view, pixels per view step.
        offset: ``(2,)`` ``(dr, dc)`` = (source row - target row, source col - target col).

    Returns:
        ``image`` resampled into the target grid, same shape and dtype as ``image``.

    Raises:
        ValueError: if ``image`` is not 2-D/3-D, ``disparity`` is not ``(H, W)`` of the
            image, or ``offset`` is not a pair.

    References:
        Thesis Sec. 6.2 (reprojection between views), Sec. 7.1 (eq 7.15 warping loss).
    """
    image = jnp.asarray(image)
    disparity = jnp.asarray(disparity)
    if image.ndim not in (2, 3):
        raise ValueError(f"image must have shape (H, W) or (H, W, C); got {image.shape}")
    H, W = image.shape[:2]
    if disparity.shape != (H, W):
        raise ValueError(
            f"disparity must have the image's spatial shape {(H, W)}; got {disparity.shape}"
        )
    dr, dc = _check_offset(offset)
    return _backward_warp(image, disparity, dr, dc)


def _sample_coords(disparity: Array, dr: Array, dc: Array, dtype):
    """The four source pixels of the bilinear sample ``(x - dc d, y - dr d)`` of every target
    pixel, clamped to the image: ``(y0, x0, y1, x1)`` (int32) and the fractions ``(fy, fx)``."""
    H, W = disparity.shape
    ys, xs = jnp.meshgrid(jnp.arange(H, dtype=dtype), jnp.arange(W, dtype=dtype), indexing="ij")
    sx = jnp.clip(xs - dc.astype(dtype) * disparity, 0.0, W - 1)
    sy = jnp.clip(ys - dr.astype(dtype) * disparity, 0.0, H - 1)
    x0f = jnp.clip(jnp.floor(sx), 0, max(W - 2, 0))
    y0f = jnp.clip(jnp.floor(sy), 0, max(H - 2, 0))
    y0, x0 = y0f.astype(jnp.int32), x0f.astype(jnp.int32)
    # fx in [0, 1]; == 1 only at the last column
    return y0, x0, jnp.minimum(y0 + 1, H - 1), jnp.minimum(x0 + 1, W - 1), sy - y0f, sx - x0f


def _blend(v00, v01, v10, v11, fy, fx):
    """Bilinear blend of the samples at ``(y0, x0), (y0, x1), (y1, x0), (y1, x1)``."""
    top = v00 * (1 - fx) + v01 * fx
    bot = v10 * (1 - fx) + v11 * fx
    return top * (1 - fy) + bot * fy


@jax.jit
def _backward_warp(image, disparity, dr, dc):
    dtype = jnp.result_type(image.dtype, disparity.dtype)
    y0, x0, y1, x1, fy, fx = _sample_coords(disparity.astype(dtype), dr, dc, dtype)
    img = image.astype(dtype)
    if img.ndim == 3:
        fx = fx[..., None]
        fy = fy[..., None]
    out = _blend(img[y0, x0], img[y0, x1], img[y1, x0], img[y1, x1], fy, fx)
    return out.astype(image.dtype)


def backward_warp_planar(
    planes: Float[ArrayLike, "C H W"],
    disparity: Float[ArrayLike, "H W"],
    offset: ArrayLike,
) -> Float[Array, "C H W"]:
    """`backward_warp` of a channels-first image: the same values, faster where many views
    are warped and compared.

    XLA on the CPU gathers from a channels-last ``(H, W, C)`` array slowly once the gather is
    fused with what consumes it: 17 views warped and compared with a reference took 435 ms
    channels-last against 165 ms channels-first (512², 2-core CPU). Transpose the views once
    (``jnp.moveaxis(views, -1, -3)``) and warp the planes.

    Args:
        planes: ``(C, H, W)`` float source view, channels first, at angular offset
            ``offset = (dr, dc)`` (view steps) from the target view.
        disparity: ``(H, W)`` float disparity of the TARGET view, pixels per view step.
        offset: ``(2,)`` ``(dr, dc)`` = (source row - target row, source col - target col).

    Returns:
        ``(C, H, W)`` resampled planes, dtype of ``planes``.

    Raises:
        ValueError: if ``planes`` is not 3-D, ``disparity`` is not ``(H, W)`` of the planes,
            or ``offset`` is not a pair.

    References:
        Thesis Sec. 6.2, Sec. 7.1 (eq 7.15).
    """
    planes = jnp.asarray(planes)
    disparity = jnp.asarray(disparity)
    if planes.ndim != 3:
        raise ValueError(f"planes must have shape (C, H, W); got {planes.shape}")
    if disparity.shape != planes.shape[1:]:
        raise ValueError(
            f"disparity must have the planes' spatial shape {planes.shape[1:]}; "
            f"got {disparity.shape}"
        )
    dr, dc = _check_offset(offset)
    return _backward_warp_planar(planes, disparity, dr, dc)


@jax.jit
def _backward_warp_planar(planes, disparity, dr, dc):
    W = planes.shape[2]
    dtype = jnp.result_type(planes.dtype, disparity.dtype)
    y0, x0, y1, x1, fy, fx = _sample_coords(disparity.astype(dtype), dr, dc, dtype)
    # Flat indices into each plane: one 1-D gather per corner and channel.
    corners = (y0 * W + x0, y0 * W + x1, y1 * W + x0, y1 * W + x1)
    out = []
    for c in range(planes.shape[0]):
        p = planes[c].astype(dtype).reshape(-1)
        out.append(_blend(*(jnp.take(p, i, mode="clip") for i in corners), fy, fx))
    return jnp.stack(out).astype(planes.dtype)


def forward_project(
    disparity: Float[ArrayLike, "H W"],
    offset: ArrayLike,
    *,
    mask: Bool[ArrayLike, "H W"] | None = None,
    fill_cracks: bool = True,
    crack_parallax: float = 0.5,
) -> tuple[Float[Array, "H W"], Bool[Array, "H W"]]:
    """Project a view's disparity map into another view (z-buffered forward warp).

    Source pixel ``(x, y)`` with disparity ``d`` lands on the destination pixel
    ``(round(x - dc * d), round(y - dr * d))``; when several land on the same pixel the
    largest disparity (nearest point) wins. Destination pixels that nothing lands on are holes
    (``valid = False``, value 0): disocclusions and the strip that leaves the image.

    Crack filling (``fill_cracks=True``). Rounding leaves 1-pixel cracks inside a surface that
    is stretched by the projection (a slanted surface, where ``|dc * d|`` has a fractional
    part that changes across the image), and a crack in a near surface lets a farther surface
    "bleed through". Both are repaired with a mesh rule: for every destination pixel ``p`` and
    each of the four neighbour pairs ``(p - e, p + e)``, ``e`` in {(0,1), (1,0), (1,1), (1,-1)},
    if the two neighbours were won by source pixels that are 8-neighbours in the source grid
    and whose parallax difference ``|d_a - d_b| * ||offset||`` is at most ``crack_parallax``
    pixels (one continuous surface, stretched by less than ``1 + crack_parallax``), then the
    surface spans ``p``: ``p`` gets ``(d_a + d_b) / 2`` if it is a hole or holds a point
    farther than ``min(d_a, d_b) - |d_a - d_b|`` (occluded by that surface). The nearest
    candidate wins.

    What stays a hole: a disocclusion, because the source pixels on the two sides of a depth
    step have a parallax difference of about the hole width (> ``crack_parallax``); only a
    disocclusion narrower than ``crack_parallax`` px whose rounding left a 1-px hole is filled
    (with the mean of the two sides, an error below ``crack_parallax / ||offset||``). A 1-px
    gap that exists in the source itself (a thin slit) is kept, because the pixels on its two
    sides are not source-adjacent. Cracks wider than one pixel (stretch >= 2: extreme
    grazing surfaces) are not filled. Tested in ``tests/lightfield/test_lightfield_warp.py``.

    ``jit``/``vmap``-able (``offset`` may be traced; for many projections prefer
    `forward_project_views`); the values are gathered from the input,
    so the output is differentiable w.r.t. ``disparity`` (not w.r.t. the landing positions).

    Args:
        disparity: ``(H, W)`` float disparity of the SOURCE view (pixels per view step).
        offset: ``(2,)`` ``(dr, dc)`` of the destination view relative to the source view
            (destination row - source row, destination col - source col), in view steps.
        mask: optional ``(H, W)`` bool, ``True`` where the source disparity is valid; invalid
            (and non-finite) source pixels are not projected.
        fill_cracks: repair 1-pixel cracks of stretched surfaces (see above).
        crack_parallax: continuity threshold, pixels of parallax difference between
            source-adjacent pixels (>= 0; a float or a traced scalar, no recompilation).

    Returns:
        ``(projected, valid)``: ``(H, W)`` disparity in the destination view (0 at holes) and
        ``(H, W)`` bool validity.

    Raises:
        ValueError: on a non-2-D disparity, a mask of another shape, a bad offset or a
            negative ``crack_parallax``.

    Warns:
        GpuCompileWarning: when the crack fill is compiled for a GPU (traced with
            ``fill_cracks`` while JAX's default device is a GPU).

    References:
        Thesis Sec. 6.1 (reprojection with a z-buffer, holes kept for angular inpainting),
        eqs 6.9-6.10 (view consistency).
    """
    disparity = jnp.asarray(disparity)
    if disparity.ndim != 2:
        raise ValueError(f"disparity must have shape (H, W); got {disparity.shape}")
    H, W = disparity.shape
    if mask is not None:
        mask = jnp.asarray(mask)
        if mask.shape != (H, W):
            raise ValueError(f"mask must have shape {(H, W)}; got {mask.shape}")
    _check_crack_parallax(crack_parallax)
    dr, dc = _check_offset(offset)
    vals, valid = _forward_project(
        disparity[None],
        None if mask is None else mask[None],
        dr[None],
        dc[None],
        crack_parallax,
        fill_cracks=fill_cracks,
    )
    return vals[0], valid[0]


def forward_project_views(
    disparity: Float[ArrayLike, "K H W"],
    offsets: Float[ArrayLike, "K 2"],
    *,
    mask: Bool[ArrayLike, "K H W"] | None = None,
    fill_cracks: bool = True,
    crack_parallax: float = 0.5,
) -> tuple[Float[Array, "K H W"], Bool[Array, "K H W"]]:
    """`forward_project` of ``K`` maps at once: map ``k`` into the view at ``offsets[k]``.

    The same values as ``jax.vmap(forward_project)`` over the maps and offsets, computed
    with one z-buffer over all ``K`` frames (flat indices offset per frame), so the program
    holds unbatched scatters only. On an NVIDIA H200 with JAX 0.11.2, XLA compiled the crack
    fill into wrong code (wrong filled pixels in float64, wrong gradients in float32 and
    float64; the projection without it was right): on a GPU it warns (`GpuCompileWarning`);
    compare with the CPU before relying on it (`experiments/gpu_projection_check.py`;
    docs/RESULTS.md, "The crack fill compiles to wrong code").

    Args:
        disparity: ``(K, H, W)`` float disparity of the source view of each projection, or
            ``(H, W)``: one map projected into every offset.
        offsets: ``(K, 2)`` ``(dr, dc)`` of each destination view relative to its source
            view, in view steps.
        mask: optional ``(K, H, W)`` (or ``(H, W)``) bool, ``True`` where the source
            disparity is valid.
        fill_cracks: repair 1-pixel cracks of stretched surfaces (`forward_project`).
        crack_parallax: continuity threshold, pixels (>= 0; a float or a traced scalar).

    Returns:
        ``(projected, valid)``: ``(K, H, W)`` disparity in each destination view (0 at
        holes) and ``(K, H, W)`` bool validity.

    Raises:
        ValueError: on a disparity that is not ``(H, W)`` or ``(K, H, W)``, offsets that are
            not ``(K, 2)``, a mask of another shape or a negative ``crack_parallax``.

    Warns:
        GpuCompileWarning: when the crack fill is compiled for a GPU (traced with
            ``fill_cracks`` while JAX's default device is a GPU).

    References:
        Thesis Sec. 6.1 (reprojection with a z-buffer), eqs 6.9-6.10 (view consistency).
    """
    disparity = jnp.asarray(disparity)
    offsets = jnp.asarray(offsets)
    if offsets.ndim != 2 or offsets.shape[1] != 2:
        raise ValueError(f"offsets must have shape (K, 2); got {offsets.shape}")
    K = offsets.shape[0]
    if disparity.ndim == 2:
        disparity = jnp.broadcast_to(disparity, (K, *disparity.shape))
    if disparity.ndim != 3 or disparity.shape[0] != K:
        raise ValueError(
            f"disparity must have shape (H, W) or ({K}, H, W) for {K} offsets; "
            f"got {disparity.shape}"
        )
    if mask is not None:
        mask = jnp.asarray(mask)
        if mask.shape == disparity.shape[1:]:
            mask = jnp.broadcast_to(mask, disparity.shape)
        if mask.shape != disparity.shape:
            raise ValueError(f"mask must have shape {disparity.shape}; got {mask.shape}")
    _check_crack_parallax(crack_parallax)
    return _forward_project(
        disparity, mask, offsets[:, 0], offsets[:, 1], crack_parallax, fill_cracks=fill_cracks
    )


def _check_crack_parallax(crack_parallax) -> None:
    check_lower_bound("crack_parallax", crack_parallax, 0.0)


@functools.partial(jax.jit, static_argnames=("fill_cracks",))
def _forward_project(disparity, mask, dr, dc, crack_parallax, *, fill_cracks: bool):
    """``(K, H, W)`` maps, ``(K,)`` offsets: the z-buffer, then the crack fill."""
    vals, valid, src = _zbuffer(disparity, mask, dr, dc)
    if not fill_cracks:
        return vals, valid
    _warn_on_gpu()
    return _fill_cracks(vals, valid, src, dr, dc, crack_parallax)


def _zbuffer(disparity, mask, dr, dc):
    """The z-buffered projection: ``(vals, valid, src)``, ``(K, H, W)`` each, ``src`` the
    winning source pixel's flat index in its frame (-1 at holes). One flat z-buffer of
    ``K (H W + 1)`` slots (each frame's last slot is its dump slot)."""
    K, H, W = disparity.shape
    dtype = disparity.dtype if jnp.issubdtype(disparity.dtype, jnp.floating) else jnp.float32
    d = disparity.astype(dtype)
    dr = dr.astype(dtype)[:, None, None]
    dc = dc.astype(dtype)[:, None, None]
    ys, xs = jnp.meshgrid(jnp.arange(H, dtype=dtype), jnp.arange(W, dtype=dtype), indexing="ij")
    tx = jnp.floor(xs - dc * d + 0.5)
    ty = jnp.floor(ys - dr * d + 0.5)
    ok = jnp.isfinite(d) & (tx >= 0) & (tx <= W - 1) & (ty >= 0) & (ty <= H - 1)
    if mask is not None:
        ok = ok & mask
    n = H * W
    txi = jnp.where(ok, tx, 0).astype(jnp.int32)
    tyi = jnp.where(ok, ty, 0).astype(jnp.int32)
    frame = (jnp.arange(K, dtype=jnp.int32) * (n + 1))[:, None, None]
    dest = (jnp.where(ok, tyi * W + txi, n) + frame).ravel()  # n: the frame's dump slot
    dflat = jnp.where(ok, d, -jnp.inf).ravel()
    zbuf = jnp.full((K * (n + 1),), -jnp.inf, dtype).at[dest].max(dflat)
    winner = ok.ravel() & (dflat == zbuf[dest])
    index = jnp.broadcast_to(jnp.arange(n, dtype=jnp.int32), (K, n)).ravel()
    src = (
        jnp.full((K * (n + 1),), -1, jnp.int32)
        .at[dest]
        .max(jnp.where(winner, index, -1))
        .reshape(K, n + 1)[:, :n]
    )
    valid = src >= 0
    safe = jnp.maximum(src, 0)
    # Gather (not the scatter result) so that gradients reach the winning source pixels; flat
    # indices, so that the gradient's scatter-add is unbatched too.
    first = (jnp.arange(K, dtype=jnp.int32) * n)[:, None]
    vals = jnp.where(valid, d.ravel()[(safe + first).ravel()].reshape(K, n), 0.0)
    return vals.reshape(K, H, W), valid.reshape(K, H, W), src.reshape(K, H, W)


def _fill_cracks(vals, valid, src, dr, dc, crack_parallax):
    """`forward_project`'s mesh rule on the z-buffer's output (``dr``, ``dc``: ``(K,)``)."""
    K, H, W = vals.shape
    dtype = vals.dtype
    dr = dr.astype(dtype)[:, None, None]
    dc = dc.astype(dtype)[:, None, None]
    sy, sx = src // W, src % W
    norm = jnp.sqrt(dr * dr + dc * dc)

    def shifted(a, oy, ox, fillv):
        # out[k, y, x] = a[k, y + oy, x + ox], fillv outside.
        p = jnp.pad(a, ((0, 0), (1, 1), (1, 1)), constant_values=fillv)
        return p[:, 1 + oy : 1 + oy + H, 1 + ox : 1 + ox + W]

    best = jnp.full((K, H, W), -jnp.inf, dtype)
    for ey, ex in ((0, 1), (1, 0), (1, 1), (1, -1)):
        va, vb = shifted(valid, -ey, -ex, False), shifted(valid, ey, ex, False)
        da, db = shifted(vals, -ey, -ex, 0.0), shifted(vals, ey, ex, 0.0)
        ya, yb = shifted(sy, -ey, -ex, -10), shifted(sy, ey, ex, 10)
        xa, xb = shifted(sx, -ey, -ex, -10), shifted(sx, ey, ex, 10)
        cheb = jnp.maximum(jnp.abs(ya - yb), jnp.abs(xa - xb))
        diff = jnp.abs(da - db)
        lo = jnp.minimum(da, db)
        ok_pair = (
            va & vb & (cheb == 1) & (diff * norm <= crack_parallax) & (~valid | (vals < lo - diff))
        )
        best = jnp.maximum(best, jnp.where(ok_pair, 0.5 * (da + db), -jnp.inf))
    fill = best > -jnp.inf
    return jnp.where(fill, best, vals), valid | fill
