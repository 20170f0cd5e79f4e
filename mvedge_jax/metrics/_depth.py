"""Disparity accuracy metrics (SPEC §7; thesis Sec. 6.2.3 and 7.2, HCI 4D benchmark).

Two protocols:

* ``"full"``: every (masked) pixel of the map; the quantile interpolates linearly (numpy's
  default). The project's own tables use it.
* ``"hci"``: the HCI 4D Light Field Benchmark's evaluation (Honauer et al., ACCV 2016; the
  definitions of its evaluation toolkit, github.com/lightfield-analysis/evaluation-toolkit,
  ``source/toolkit/metrics/general_metrics.py``, ``region_metrics.py`` and
  ``scenes/base_scene.py``): a ``HCI_BORDER`` = 15 pixel frame on each side is excluded
  (``BaseScene.get_boundary_mask``); BadPix(t) is the percentage of evaluated pixels with
  ``|d − gt| > t`` (``BadPix``, t = 0.07 by default); MSE×100 is the mean squared error ×100
  (``MSE``); Q25 is the order statistic ``sort(100 |d − gt|)[int(0.25 n)]`` of the ``n``
  evaluated pixels, no interpolation (``Quantile``). Per-scene region masks
  (``mask_<region>_lowres.png``, `read_region_masks`) give the region metrics:
  BadPix(0.07) on ``discontinuities`` (``Discontinuities``) and the bumpiness on ``planes``
  and ``smooth_surfaces`` (``BumpinessPlanes``, ``BumpinessContinSurf``: mean of the
  Frobenius norm of the Hessian of ``d − gt``, clipped to 0.05, ×100; `bumpiness_x100`).
  NaN pixels of ``d`` or ``gt`` are left out, as the toolkit's ``get_mask_valid`` does.

Official scores differ on three scenes: the toolkit evaluates the stratified scenes
backgammon, dots and stripes against a 10× high-resolution ground truth
(``gt_disp_highres.pfm``, ``general_metrics_high_res``) and the discontinuity and fine-structure
metrics of every scene at high resolution; ``../shared/data`` holds only the low-resolution
``gt_disp_lowres.pfm``, so the ``"hci"`` numbers here are the low-resolution evaluation (the
one the toolkit applies to the photorealistic training scenes).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

BADPIX_THRESHOLDS = (0.01, 0.03, 0.07, 0.1, 0.3, 0.7)
#: Pixels excluded on each side of the map by the HCI 4D benchmark (``boundary_offset``).
HCI_BORDER = 15
#: The benchmark's BadPix threshold (``settings.BAD_PIX_THRESH``), pixels per view step.
HCI_BADPIX_THRESHOLD = 0.07
#: Clip of the bumpiness metric (``BumpinessPlanes(clip=0.05)``).
BUMPINESS_CLIP = 0.05
#: Region masks of the HCI 4D photorealistic scenes (``mask_<name>_lowres.png``).
REGION_MASKS = ("discontinuities", "planes", "smooth_surfaces")
PROTOCOLS = ("full", "hci")


def _prepare(d, gt, mask) -> tuple[Array, Array, Array]:
    d = jnp.asarray(d)
    gt = jnp.asarray(gt)
    if d.shape != gt.shape:
        raise ValueError(f"disparity and ground truth shapes differ: {d.shape} vs {gt.shape}")
    if d.size == 0:
        raise ValueError(f"empty disparity map of shape {d.shape}")
    if mask is None:
        m = jnp.ones(d.shape, bool)
    else:
        m = jnp.asarray(mask)
        if m.shape != d.shape:
            raise ValueError(f"mask shape {m.shape} differs from the disparity shape {d.shape}")
        if m.dtype != jnp.bool_:
            raise ValueError(f"mask must be boolean; got dtype {m.dtype}")
    dtype = jnp.result_type(d.dtype, gt.dtype, jnp.float32)
    return d.astype(dtype), gt.astype(dtype), m


def _masked_mean(x: Array, m: Array) -> Array:
    # NaN when the mask is empty (0/0), like numpy's mean of an empty selection.
    return jnp.sum(jnp.where(m, x, 0.0)) / jnp.sum(m)


def mse_x100(
    d: Float[ArrayLike, "*shape"],
    gt: Float[ArrayLike, "*shape"],
    mask: Bool[ArrayLike, "*shape"] | None = None,
) -> Float[Array, ""]:
    """Mean squared disparity error ×100 over the (masked) pixels.

    Args:
        d: estimated disparity, any shape (e.g. ``(H, W)``), pixels per view step.
        gt: ground truth, same shape.
        mask: optional bool, same shape; ``True`` pixels are evaluated.

    Returns:
        ``()`` float: ``100 · mean((d - gt)²)``; NaN for an empty mask.

    Raises:
        ValueError: on mismatched shapes or a non-boolean mask.

    References:
        Thesis Sec. 6.2.3 (MSE×100); Honauer et al., ACCV 2016.
    """
    d, gt, m = _prepare(d, gt, mask)
    return _mse_x100(d, gt, m)


def badpix(
    d: Float[ArrayLike, "*shape"],
    gt: Float[ArrayLike, "*shape"],
    t: float | Float[ArrayLike, ""],
    mask: Bool[ArrayLike, "*shape"] | None = None,
) -> Float[Array, ""]:
    """Percentage of (masked) pixels whose absolute disparity error exceeds ``t``.

    Args:
        d: estimated disparity, any shape.
        gt: ground truth, same shape.
        t: threshold in pixels per view step (0.01, 0.03, 0.07 on HCI 4D); may be traced.
        mask: optional bool, same shape.

    Returns:
        ``()`` float in [0, 100]; NaN for an empty mask.

    Raises:
        ValueError: on mismatched shapes or a non-boolean mask.

    References:
        Thesis Sec. 7.2 (BadPix); Honauer et al., ACCV 2016.
    """
    d, gt, m = _prepare(d, gt, mask)
    return _badpix(d, gt, jnp.asarray(t, d.dtype), m)


def _masked_quantile(x: Array, m: Array, q: float) -> Array:
    """``np.quantile(x[m], q)`` (linear interpolation) with static shapes."""
    v = jnp.sort(jnp.where(m, x, jnp.inf).ravel())
    n = jnp.sum(m)
    pos = q * (n - 1).astype(x.dtype)
    lo = jnp.clip(jnp.floor(pos).astype(jnp.int32), 0, v.size - 1)
    hi = jnp.clip(lo + 1, 0, jnp.maximum(n - 1, 0))
    frac = pos - lo.astype(x.dtype)
    out = v[lo] + frac * (v[hi] - v[lo])
    return jnp.where(n > 0, out, jnp.nan)


def q25_x100(
    d: Float[ArrayLike, "*shape"],
    gt: Float[ArrayLike, "*shape"],
    mask: Bool[ArrayLike, "*shape"] | None = None,
) -> Float[Array, ""]:
    """25th percentile of the absolute disparity error ×100 over the (masked) pixels.

    The percentile interpolates linearly between order statistics (numpy's default).

    Args:
        d: estimated disparity, any shape.
        gt: ground truth, same shape.
        mask: optional bool, same shape.

    Returns:
        ``()`` float; NaN for an empty mask.

    Raises:
        ValueError: on mismatched shapes or a non-boolean mask.

    References:
        Thesis Sec. 6.2.3 (Q25, reported ×100 in Table 6.1).
    """
    d, gt, m = _prepare(d, gt, mask)
    return _q25_x100(d, gt, m)


@jax.jit
def _mse_x100(d, gt, m):
    return 100.0 * _masked_mean((d - gt) ** 2, m)


@jax.jit
def _badpix(d, gt, t, m):
    return 100.0 * _masked_mean((jnp.abs(d - gt) > t).astype(d.dtype), m)


@jax.jit
def _q25_x100(d, gt, m):
    return 100.0 * _masked_quantile(jnp.abs(d - gt), m, 0.25)


@jax.jit
def _all_metrics(d, gt, m):
    err = jnp.abs(d - gt)
    out = {"mse_x100": 100.0 * _masked_mean(err**2, m)}
    for t in BADPIX_THRESHOLDS:
        out[f"badpix_{t}"] = 100.0 * _masked_mean((err > t).astype(d.dtype), m)
    out["q25_x100"] = 100.0 * _masked_quantile(err, m, 0.25)
    return out


def depth_metrics(
    d: Float[ArrayLike, "*shape"],
    gt: Float[ArrayLike, "*shape"],
    mask: Bool[ArrayLike, "*shape"] | None = None,
    *,
    protocol: str = "full",
    regions: Mapping[str, Bool[ArrayLike, "H W"]] | None = None,
    border: int = HCI_BORDER,
) -> dict[str, float]:
    """All accuracy metrics of SPEC §7 as plain Python floats (for reports and tables).

    Args:
        d: estimated disparity, any shape (usually the centre view ``(H, W)``; ``(H, W)``
            for ``protocol="hci"``).
        gt: ground truth, same shape.
        mask: optional bool, same shape.
        protocol: ``"full"`` (every masked pixel; Q25 interpolated linearly) or ``"hci"``
            (`benchmark_metrics`: the HCI 4D benchmark's border, Q25 and region metrics).
        regions: with ``"hci"``, region masks ``{name: (H, W) bool}`` (`read_region_masks`).
        border: with ``"hci"``, pixels excluded on each side (default `HCI_BORDER`).

    Returns:
        ``{"mse_x100", "badpix_0.01", "badpix_0.03", "badpix_0.07", "badpix_0.1",
        "badpix_0.3", "badpix_0.7", "q25_x100"}`` → float (badpix in percent); with
        ``"hci"`` also the region metrics of `benchmark_metrics`.

    Raises:
        ValueError: on mismatched shapes, a non-boolean mask or an unknown protocol.

    References:
        Thesis Sec. 6.2.3, 7.2; Honauer et al., ACCV 2016.
    """
    if protocol not in PROTOCOLS:
        raise ValueError(f"protocol must be one of {PROTOCOLS}; got {protocol!r}")
    if protocol == "hci":
        return benchmark_metrics(d, gt, mask, regions=regions, border=border)
    if regions is not None:
        raise ValueError('regions are evaluated by protocol="hci" only')
    d, gt, m = _prepare(d, gt, mask)
    values = _all_metrics(d, gt, m)  # (jit returns the dict with sorted keys)
    keys = ["mse_x100", *(f"badpix_{t}" for t in BADPIX_THRESHOLDS), "q25_x100"]
    return {k: float(values[k]) for k in keys}


def border_mask(shape: tuple[int, int], border: int = HCI_BORDER) -> Bool[np.ndarray, "H W"]:
    """The HCI 4D benchmark's evaluation frame: ``False`` on ``border`` pixels at each side.

    Args:
        shape: ``(H, W)`` of the map.
        border: pixels excluded on each side (``>= 0``).

    Returns:
        ``(H, W)`` bool NumPy mask.

    Raises:
        ValueError: on a negative border or one that leaves no pixel.

    References:
        Honauer et al., ACCV 2016; evaluation toolkit ``BaseScene.get_boundary_mask``.
    """
    if len(shape) != 2:
        raise ValueError(f"border_mask needs an (H, W) shape; got {tuple(shape)}")
    H, W = (int(s) for s in shape)
    if border < 0 or 2 * border >= min(H, W):
        raise ValueError(f"border {border} must be >= 0 and leave pixels of an {H}x{W} map")
    m = np.zeros((H, W), bool)
    m[border : H - border, border : W - border] = True
    return m


def q25_hci_x100(
    d: Float[ArrayLike, "*shape"],
    gt: Float[ArrayLike, "*shape"],
    mask: Bool[ArrayLike, "*shape"] | None = None,
) -> Float[Array, ""]:
    """Q25 as the HCI 4D benchmark defines it: ``sort(100 |d − gt|)[int(0.25 n)]``.

    The order statistic at index ``floor(0.25 n)`` (0-based) of the ``n`` masked errors,
    without interpolation (`q25_x100` interpolates linearly instead).

    Args:
        d: estimated disparity, any shape.
        gt: ground truth, same shape.
        mask: optional bool, same shape.

    Returns:
        ``()`` float; NaN for an empty mask.

    Raises:
        ValueError: on mismatched shapes or a non-boolean mask.

    References:
        Honauer et al., ACCV 2016; evaluation toolkit ``metrics.general_metrics.Quantile``.
    """
    d, gt, m = _prepare(d, gt, mask)
    return _q25_hci(d, gt, m)


@jax.jit
def _q25_hci(d, gt, m):
    v = jnp.sort(jnp.where(m, 100.0 * jnp.abs(d - gt), jnp.inf).ravel())
    n = jnp.sum(m)
    idx = jnp.clip((n * 25) // 100, 0, v.size - 1)
    return jnp.where(n > 0, v[idx], jnp.nan)


def _scharr(x: Array, axis: int) -> Array:
    """Scharr derivative along ``axis`` of ``(H, W)``: kernel ``[3, 10, 3] ⊗ [1, 0, −1] / 16``
    (the normalisation of scikit-image's ``scharr_h/v`` that the toolkit used), reflected
    edges, the 1-pixel frame set to 0 (as scikit-image masks it)."""
    p = jnp.pad(x, 1, mode="symmetric")
    H, W = x.shape
    if axis == 1:
        diff = p[:, 2:] - p[:, :-2]  # (H + 2, W)
        out = (3 * diff[:-2] + 10 * diff[1:-1] + 3 * diff[2:]) / 16.0
    else:
        diff = p[2:] - p[:-2]  # (H, W + 2)
        out = (3 * diff[:, :-2] + 10 * diff[:, 1:-1] + 3 * diff[:, 2:]) / 16.0
    frame = jnp.zeros((H, W), bool).at[1:-1, 1:-1].set(True)
    return jnp.where(frame, out, 0.0)


@jax.jit
def _bumpiness(d, gt, m, clip):
    diff = d - gt
    dx, dy = _scharr(diff, 1), _scharr(diff, 0)
    hess = _scharr(dx, 1) ** 2 + _scharr(dx, 0) ** 2 + _scharr(dy, 0) ** 2 + _scharr(dy, 1) ** 2
    b = jnp.clip(jnp.sqrt(hess), 0.0, clip)
    ok = m & jnp.isfinite(b)
    return 100.0 * _masked_mean(b, ok)


def bumpiness_x100(
    d: Float[ArrayLike, "H W"],
    gt: Float[ArrayLike, "H W"],
    mask: Bool[ArrayLike, "H W"] | None = None,
    *,
    clip: float = BUMPINESS_CLIP,
) -> Float[Array, ""]:
    """The HCI 4D benchmark's bumpiness ×100: mean over the mask of
    ``min(‖Hess(d − gt)‖_F, clip)`` (Scharr derivatives), ×100.

    It measures how much the error surface curves (0 for an error that is constant or
    linear over the region), so a planar surface estimated as planar but offset scores 0.

    Args:
        d: ``(H, W)`` estimated disparity.
        gt: ``(H, W)`` ground truth.
        mask: optional ``(H, W)`` bool (the benchmark: ``mask_planes`` or
            ``mask_smooth_surfaces`` inside the border frame).
        clip: clip of the per-pixel norm (the benchmark's 0.05).

    Returns:
        ``()`` float; NaN for an empty mask.

    Raises:
        ValueError: on mismatched or non-2-D shapes or a non-boolean mask.

    References:
        Honauer et al., ACCV 2016 (Sec. 4, "bumpiness"); evaluation toolkit
        ``metrics.region_metrics.BumpinessPlanes.get_bumpiness``.
    """
    d, gt, m = _prepare(d, gt, mask)
    if d.ndim != 2:
        raise ValueError(f"bumpiness needs (H, W) maps; got shape {tuple(d.shape)}")
    return _bumpiness(d, gt, m, jnp.asarray(clip, d.dtype))


def benchmark_metrics(
    d: Float[ArrayLike, "H W"],
    gt: Float[ArrayLike, "H W"],
    mask: Bool[ArrayLike, "H W"] | None = None,
    *,
    regions: Mapping[str, Bool[ArrayLike, "H W"]] | None = None,
    border: int = HCI_BORDER,
) -> dict[str, float]:
    """The HCI 4D benchmark protocol (see the module docstring) as plain Python floats.

    Evaluated pixels: inside the ``border`` frame, in ``mask`` (if given), finite in ``d``
    and ``gt``.

    Args:
        d: ``(H, W)`` estimated disparity of the centre view, pixels per view step.
        gt: ``(H, W)`` ground truth (low resolution, e.g. ``gt_disp_lowres.pfm``).
        mask: optional ``(H, W)`` bool of valid ground truth.
        regions: optional ``{name: (H, W) bool}`` region masks (`read_region_masks`); each
            region ``r`` adds ``"r_mse_x100"`` and ``"r_badpix_0.07"`` (the benchmark's
            ``Discontinuities`` score for ``r = "discontinuities"``), and
            ``"r_bumpiness_x100"`` for ``planes`` and ``smooth_surfaces``.
        border: pixels excluded on each side (default `HCI_BORDER` = 15).

    Returns:
        ``{"mse_x100", "badpix_<t>" for t in BADPIX_THRESHOLDS, "q25_x100"}`` (Q25 by
        `q25_hci_x100`) plus the region keys.

    Raises:
        ValueError: on mismatched or non-2-D shapes, a non-boolean mask or region mask, or
            a border that leaves no pixel.

    References:
        Honauer et al., "A dataset and evaluation methodology for depth estimation on 4D
        light fields", ACCV 2016; evaluation toolkit (``general_metrics.py``,
        ``region_metrics.py``).
    """
    d, gt, m = _prepare(d, gt, mask)
    if d.ndim != 2:
        raise ValueError(f"the benchmark protocol needs (H, W) maps; got shape {tuple(d.shape)}")
    frame = jnp.asarray(border_mask(d.shape, border))
    valid = m & frame & jnp.isfinite(d) & jnp.isfinite(gt)
    d0 = jnp.where(jnp.isfinite(d), d, 0.0)
    g0 = jnp.where(jnp.isfinite(gt), gt, 0.0)
    values = _all_metrics(d0, g0, valid)
    out = {"mse_x100": float(values["mse_x100"])}
    out.update({f"badpix_{t}": float(values[f"badpix_{t}"]) for t in BADPIX_THRESHOLDS})
    out["q25_x100"] = float(_q25_hci(d0, g0, valid))
    for name, region in (regions or {}).items():
        r = jnp.asarray(region)
        if r.shape != d.shape or r.dtype != jnp.bool_:
            raise ValueError(
                f"region mask {name!r} must be bool of shape {tuple(d.shape)}; got "
                f"{r.dtype} {tuple(r.shape)}"
            )
        rv = valid & r
        t = HCI_BADPIX_THRESHOLD
        out[f"{name}_mse_x100"] = float(_mse_x100(d0, g0, rv))
        out[f"{name}_badpix_{t}"] = float(_badpix(d0, g0, jnp.asarray(t, d0.dtype), rv))
        if name in ("planes", "smooth_surfaces"):
            clip = jnp.asarray(BUMPINESS_CLIP, d0.dtype)
            out[f"{name}_bumpiness_x100"] = float(_bumpiness(d0, g0, rv, clip))
    return out


def read_region_masks(
    scene_dir: str | os.PathLike, names: tuple[str, ...] = REGION_MASKS
) -> dict[str, Bool[np.ndarray, "H W"]]:
    """The HCI 4D region masks of a scene folder that exist (``mask_<name>_lowres.png``).

    A pixel belongs to the region where the PNG is non-zero (the toolkit casts the image to
    bool). Missing files are skipped (the stratified and additional scenes and the copies in
    ``../shared/data`` have none).

    Args:
        scene_dir: the scene folder.
        names: region names to look for (default `REGION_MASKS`).

    Returns:
        ``{name: (H, W) bool}`` for the masks present (possibly empty).

    Raises:
        FileNotFoundError: if ``scene_dir`` is not a folder.
        ValueError: if a mask file cannot be decoded.

    References:
        Honauer et al., ACCV 2016; evaluation toolkit ``BaseScene.get_mask``.
    """
    from ..io import read_rgb  # the io package reads every file

    folder = Path(scene_dir)
    if not folder.is_dir():
        raise FileNotFoundError(f"scene folder not found: {folder}")
    out = {}
    for name in names:
        path = folder / f"mask_{name}_lowres.png"
        if path.is_file():
            out[name] = np.asarray(read_rgb(path)).max(axis=-1) > 0
    return out
