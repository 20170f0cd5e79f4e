"""The `LightField` container and its geometry helpers (SPEC §0)."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float


class LightField(eqx.Module):
    """A 4D light field: a U×V grid of sub-aperture views with optional ground truth.

    Array layout (SPEC §0): ``views[row, col, y, x, channel]``; rows run top to bottom,
    columns left to right; RGB float32 in [0, 1]. The centre view is ``(U // 2, V // 2)``.
    Disparity is in pixels per view step, with the sign convention
    ``centre(x, y) ≈ views[row, col](x - dc * d, y - dr * d)`` where
    ``dr = row - U // 2`` and ``dc = col - V // 2``; larger disparity is nearer.

    Attributes:
        views: ``(U, V, H, W, 3)`` float32 RGB in [0, 1]. Views absent from a partial grid
            are zero and flagged ``False`` in ``view_mask``.
        view_mask: ``(U, V)`` bool, ``True`` where the view exists.
        gt_disparity: ``(U, V, H, W)`` float32 ground-truth disparity, or ``None``.
        gt_mask: ``(U, V, H, W)`` bool, ``True`` where ``gt_disparity`` is valid, or ``None``.
        name: scene name (static metadata).
        source: folder the views were read from, or ``None`` for synthetic scenes.
        disparity_range: ``(d_min, d_max)`` in pixels per view step when known, else ``None``.

    Raises:
        ValueError: on construction, if shapes disagree, the grid is smaller than 3 in a
            direction, the cross-hair is incomplete, ``views`` is not floating point (uint8
            images must be divided by 255), ``views`` holds values outside [0, 1] (more
            than `VALUE_TOLERANCE` beyond; e.g. 0–255 floats) or NaN/Inf, ``gt_mask`` is not
            boolean, or ``gt_disparity`` is NaN/Inf where ``gt_mask`` is True. Value checks
            run on concrete arrays only (not while tracing under ``jit``/``vmap``).
    """

    views: Float[Array, "U V H W 3"]
    view_mask: Bool[Array, "U V"]
    gt_disparity: Float[Array, "U V H W"] | None = None
    gt_mask: Bool[Array, "U V H W"] | None = None
    name: str = eqx.field(static=True, default="lightfield")
    source: str | None = eqx.field(static=True, default=None)
    disparity_range: tuple[float, float] | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        shape = tuple(self.views.shape)
        if len(shape) != 5 or shape[-1] != 3:
            raise ValueError(f"LightField.views must have shape (U, V, H, W, 3); got {shape}")
        U, V, H, W, _ = shape
        if U < 3 or V < 3:
            raise ValueError(
                f"a light field needs at least 3 views in each direction; got a {U}x{V} grid"
            )
        if tuple(self.view_mask.shape) != (U, V):
            raise ValueError(
                f"LightField.view_mask must have shape {(U, V)}; got {tuple(self.view_mask.shape)}"
            )
        if self.gt_disparity is not None and tuple(self.gt_disparity.shape) != (U, V, H, W):
            raise ValueError(
                f"LightField.gt_disparity must have shape {(U, V, H, W)}; "
                f"got {tuple(self.gt_disparity.shape)}"
            )
        if (self.gt_mask is None) != (self.gt_disparity is None):
            raise ValueError("LightField.gt_mask and gt_disparity must be given together")
        if self.gt_mask is not None and tuple(self.gt_mask.shape) != (U, V, H, W):
            raise ValueError(
                f"LightField.gt_mask must have shape {(U, V, H, W)}; "
                f"got {tuple(self.gt_mask.shape)}"
            )
        _check_dtypes(self)
        # Concrete checks only (skipped while tracing, e.g. under jit/vmap).
        try:
            mask = np.asarray(self.view_mask)
        except Exception:  # a tracer: nothing concrete to check
            return
        _check_values(self)
        rc, cc = U // 2, V // 2
        if not mask[rc, :].all() or not mask[:, cc].all():
            missing = [(rc, c) for c in range(V) if not mask[rc, c]] + [
                (r, cc) for r in range(U) if not mask[r, cc]
            ]
            raise ValueError(
                f"the central cross-hair of the {U}x{V} grid is incomplete; missing views "
                f"(row, col): {missing}"
            )

    # ---- geometry -------------------------------------------------------------------------
    @property
    def grid(self) -> tuple[int, int]:
        """``(U, V)``: number of view rows and columns."""
        return int(self.views.shape[0]), int(self.views.shape[1])

    @property
    def size(self) -> tuple[int, int]:
        """``(H, W)``: view height and width in pixels."""
        return int(self.views.shape[2]), int(self.views.shape[3])

    @property
    def centre_index(self) -> tuple[int, int]:
        """``(r_c, c_c) = (U // 2, V // 2)``."""
        U, V = self.grid
        return U // 2, V // 2

    @property
    def centre_view(self) -> Float[Array, "H W 3"]:
        """The centre view, ``(H, W, 3)``."""
        rc, cc = self.centre_index
        return self.views[rc, cc]

    @property
    def centre_gt(self) -> Float[Array, "H W"] | None:
        """Ground-truth disparity of the centre view ``(H, W)``, or ``None``."""
        if self.gt_disparity is None:
            return None
        rc, cc = self.centre_index
        return self.gt_disparity[rc, cc]

    @property
    def centre_gt_mask(self) -> Bool[Array, "H W"] | None:
        """Validity mask of the centre-view ground truth ``(H, W)``, or ``None``."""
        if self.gt_mask is None:
            return None
        rc, cc = self.centre_index
        return self.gt_mask[rc, cc]

    def cross_hair(self) -> tuple[Float[Array, "V H W 3"], Float[Array, "U H W 3"]]:
        """The central cross-hair: the centre row of views ``(V, H, W, 3)`` and the centre
        column of views ``(U, H, W, 3)``."""
        rc, cc = self.centre_index
        return self.views[rc], self.views[:, cc]

    def view_offsets(self) -> tuple[Float[Array, "U V"], Float[Array, "U V"]]:
        """Per-view offsets ``(dr, dc)`` from the centre view, each ``(U, V)`` float32."""
        return view_offsets(*self.grid)

    def horizontal_epis(self, channels: Float[Array, "U V H W C"] | None = None):
        """Horizontal EPIs of the centre view row (SPEC §0). See `horizontal_epis`."""
        return horizontal_epis(self.views if channels is None else channels)

    def vertical_epis(self, channels: Float[Array, "U V H W C"] | None = None):
        """Vertical EPIs of the centre view column (SPEC §0). See `vertical_epis`."""
        return vertical_epis(self.views if channels is None else channels)


#: Views may exceed [0, 1] by this much (rounding of resampling filters); beyond it the
#: light field is refused (0–255 values, unnormalised HDR data).
VALUE_TOLERANCE = 1e-3


def _check_dtypes(lf: LightField) -> None:
    dt = np.dtype(lf.views.dtype)
    if not np.issubdtype(dt, np.floating):
        hint = " (divide 8-bit images by 255)" if dt == np.uint8 else ""
        raise ValueError(f"LightField.views must be float32 RGB in [0, 1]; got dtype {dt}{hint}")
    if lf.gt_disparity is not None and not np.issubdtype(
        np.dtype(lf.gt_disparity.dtype), np.floating
    ):
        raise ValueError(
            f"LightField.gt_disparity must be floating point; got dtype {lf.gt_disparity.dtype}"
        )
    if lf.gt_mask is not None and np.dtype(lf.gt_mask.dtype) != np.bool_:
        raise ValueError(f"LightField.gt_mask must be boolean; got dtype {lf.gt_mask.dtype}")
    if lf.view_mask.dtype != np.bool_:
        raise ValueError(f"LightField.view_mask must be boolean; got dtype {lf.view_mask.dtype}")


def _check_values(lf: LightField) -> None:
    """Range and finiteness of concrete views and ground truth."""
    try:
        views = np.asarray(lf.views)
    except Exception:  # a tracer
        return
    lo, hi = float(views.min()), float(views.max())
    if not (np.isfinite(lo) and np.isfinite(hi)):
        n = int((~np.isfinite(views)).sum())
        raise ValueError(f"LightField.views of {lf.name!r} contains {n} NaN/Inf values")
    if lo < -VALUE_TOLERANCE or hi > 1.0 + VALUE_TOLERANCE:
        hint = " (looks like 0-255 values: divide by 255)" if hi > 2.0 else ""
        raise ValueError(
            f"LightField.views of {lf.name!r} must be in [0, 1]; got values in "
            f"[{lo:.4g}, {hi:.4g}]{hint}"
        )
    if lf.gt_disparity is None:
        return
    try:
        gt, gtm = np.asarray(lf.gt_disparity), np.asarray(lf.gt_mask)
    except Exception:
        return
    bad = gtm & ~np.isfinite(gt)
    if bad.any():
        u, v, y, x = (int(i[0]) for i in np.nonzero(bad))
        raise ValueError(
            f"LightField.gt_disparity of {lf.name!r} has {int(bad.sum())} NaN/Inf values "
            f"where gt_mask is True (first at view ({u}, {v}), y={y}, x={x}); set gt_mask "
            "False there"
        )


def view_offsets(U: int, V: int) -> tuple[Float[Array, "U V"], Float[Array, "U V"]]:
    """Offsets ``(dr, dc)`` of every view from the centre view ``(U // 2, V // 2)``.

    Returns:
        Two ``(U, V)`` float32 arrays, ``dr = row - U // 2`` and ``dc = col - V // 2``.
    """
    r = jnp.arange(U, dtype=jnp.float32) - U // 2
    c = jnp.arange(V, dtype=jnp.float32) - V // 2
    dr, dc = jnp.meshgrid(r, c, indexing="ij")
    return dr, dc


def horizontal_epis(views: Float[Array, "U V H W C"]) -> Float[Array, "H V W C"]:
    """All horizontal EPIs of the centre row of views.

    ``E[y][col, x] = views[U // 2, col, y, x]``: one EPI per pixel row ``y``. A scene point at
    centre-view column ``x_c`` with disparity ``d`` traces ``x(col) = x_c - (col - V // 2) * d``.

    Args:
        views: ``(U, V, H, W, C)`` light field (any channel count).

    Returns:
        ``(H, V, W, C)``: the EPI of pixel row ``y`` is ``[y]``.
    """
    return jnp.transpose(views[views.shape[0] // 2], (1, 0, 2, 3))


def vertical_epis(views: Float[Array, "U V H W C"]) -> Float[Array, "W U H C"]:
    """All vertical EPIs of the centre column of views.

    ``E[x][row, y] = views[row, V // 2, y, x]``: one EPI per pixel column ``x``. A scene point
    at centre-view row ``y_c`` with disparity ``d`` traces ``y(row) = y_c - (row - U // 2) * d``.

    Args:
        views: ``(U, V, H, W, C)`` light field (any channel count).

    Returns:
        ``(W, U, H, C)``: the EPI of pixel column ``x`` is ``[x]``.
    """
    return jnp.transpose(views[:, views.shape[1] // 2], (2, 0, 1, 3))
