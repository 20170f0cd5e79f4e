"""`ReconstructConfig`: every option of the smooth 4D reconstruction (thesis Ch. 6)."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from ..solve import SolverConfig
from ._wmf import WEIGHT_TYPES

COLOUR_SPACES = ("lab", "rgb")
HOLE_FILLS = ("solve", "background")
MERGES = ("photo", "mean")


def _f32(x) -> Array:
    """Float array leaf (float32, or float64 when x64 is enabled)."""
    return jnp.asarray(x, dtype=jnp.result_type(float))


def _concrete(x) -> np.ndarray | None:
    try:
        return np.asarray(x)
    except Exception:  # a tracer (config built under jit/vmap): nothing to check
        return None


class ReconstructConfig(eqx.Module):
    """Configuration of the smooth 4D reconstruction (centre diffusion, sharpening,
    cross-hair projection, angular inpainting, off-cross-hair views).

    Array fields are pytree leaves (sweep / `vmap` / differentiate without recompiling);
    the others are static.

    Attributes:
        omega: ``ω`` of the centre data weight ``ω · exp(a · λ_e)`` (eq 6.3; thesis 150).
        a: exponent ``a`` of eq 6.3 (thesis 3).
        lambda_e_max: ``λ_e`` is clipped to ``[0, lambda_e_max]`` before the exponential.
        offset_scale: labels are splatted at ``p + offset_scale · n`` (``n`` the surface
            vector, pixels).
        centre_c: numerator of the centre smoothness ``c / (|∇I| + ε)``.
        centre_eps: ``ε`` of the centre smoothness, in guide units (see ``colour_space``).
        conf_beta: depth-edge confidence attenuation: smoothness across an edge is divided by
            ``1 + conf_beta · conf`` (``conf`` the larger confidence of the two pixels).
        wmf_sigma: range parameter of the weighted median filter (guide units, RGB [0, 1]).
        epi_data_weight: data weight on reprojected pixels (eq 6.8; thesis 15).
        epi_centre_weight: data weight of the centre view's row of every EPI (the estimated
            map itself; large = the centre view keeps its estimate).
        epi_photo_sigma: colour scale (RGB) of the photometric confidence of reprojected
            pixels (`photometric_confidence`), which multiplies ``epi_data_weight``; large =
            off.
        epi_hole_weight: weight, in the angular inpainting, of the background prior in
            reprojection holes (disoccluded pixels take the farther side along the EPI's
            spatial axis). On the synthetic default scene (9x9x160², with the other defaults)
            3, 10 and 30 give a worst per-view MSE×100 within 0.02 of each other; 1 is worse.
        epi_min_confidence: a reprojected pixel (off the centre row) whose photometric
            confidence is at most this counts as a hole in the angular inpainting: a value
            whose colour does not match was carried across a disocclusion (a foreground value
            spilled onto the background). 0 = every landed pixel is data (the thesis).
        epi_line_scale: multiplier of ``λ_e`` on EPI-line pixels (eq 6.8; thesis 1).
        epi_line_floor: minimum line weight (so that lines with ``λ_e ≈ 0`` still guide).
        epi_occlusion_tol: an EPI-line pixel is dropped where the reprojected disparity is
            larger (nearer) than the line's by more than this (the line is occluded there).
        epi_c: numerator ``c`` of the EPI smoothness (eq 6.7; thesis 0.1).
        epi_eps: ``ε`` of eq 6.7, guide units.
        refine_jump: photo-consistent boundary snapping (`photo_refine`) acts where the
            disparity range of the window exceeds this (pixels per view step).
        refine_margin: colour-cost advantage a candidate needs over the current value.
        matte_jump: disparity range of a window that marks a depth discontinuity for
            `boundary_matte` (pixels per view step).
        matte_min_separation: `boundary_matte` decides only where the foreground and
            background colours differ by at least this (guide units).
        matte_impure_weight: weight of window pixels on a discontinuity in the colour means.
        select_min_change: `select_centre` tests a candidate centre map only where it differs
            from the incumbent by more than this (pixels per view step).
        select_margin: colour-cost advantage the candidate needs there (L1 colour units).
        select_ssim: weight of the SSIM dissimilarity in the cost of `select_centre`
            (`photo_cost`'s ``ssim``; 0 = colour L1 only). 1 weighs it like eq 7.16, whose
            terms the Ch. 7 optimisation minimises. Measured on antinous (session 8): the
            L1 alone cannot tell disparities ±0.05 apart on the faint texture of the floor and
            background (the L1 error of the GT and of GT − 0.05 is equal there; the SSIM term
            is 5% higher), and the merge missed half the pixels the optimisation had fixed.
        fill_c: smoothness numerator of the hole-filling solve of off-cross-hair views.
        fill_data_weight: data weight of the reprojected pixels in that solve.
        fill_hole_weight: weight, in that solve, of the background fill
            (`background_fill`) on holes: large = holes take the farther neighbouring surface,
            small = the colour-guided smoothness spreads the neighbours into them.
        fill_min_confidence: a merged pixel of an off-cross-hair view whose photometric
            confidence is at most this counts as a hole (0 = only pixels nothing landed on).
        upsample: solve the centre problem on an ``upsample×`` grid (1 or 2) and average
            back (sub-pixel label placement).
        colour_space: ``"lab"`` (CIELAB / 100) or ``"rgb"`` guide for the smoothness terms.
        sharpen: apply the weighted median filter to the centre disparity (Sec. 6.1).
        wmf_radius: weighted-median window radius (thesis 7).
        wmf_weight: weighted-median weight type (see `weighted_median_filter`).
        wmf_iterations: bisection steps of the weighted median.
        refine: snap the centre disparity near depth discontinuities to the photo-consistent
            side (occlusion-aware multi-view colour test, `photo_refine`) before the weighted
            median.
        refine_radius: window radius of that test (candidates: window min and max).
        refine_iterations: passes of the centre-view refinement.
        refine_aggregate: radius of the colour-weighted cost aggregation of that test.
        matte: after the snapping and before the weighted median, put every pixel on a depth
            discontinuity of the centre map on the side its colour mixture says
            (`boundary_matte`; not in the thesis).
        matte_views: apply `boundary_matte` to every other view's final map too (reprojected
            boundaries are only pixel-accurate); ~20 ms per 512² view.
        matte_radius: window radius of `boundary_matte`.
        matte_sigma: distance scale of its colour means, pixels.
        select_aggregate: radius of the colour-weighted cost aggregation of `select_centre`.
        hole_fill: ``"solve"`` (screened-Poisson fill guided by the view) or ``"background"``
            (`background_fill` alone: the farthest of the nearest valid values left, right,
            above and below) for off-cross-hair views.
        merge: ``"photo"`` (photometric-confidence-weighted mean of the two reprojections of an
            off-cross-hair view) or ``"mean"`` (the thesis' plain mean).
        cross_hair_fill: in every cross-hair view but the centre, the holes of the
            projection (as counted by ``epi_min_confidence``) take the farther of the
            inpainted value and the 2-D `background_fill` of the view (nearest valid value
            left, right, above and below). The EPI inpainting sees one image row or column
            only: a disoccluded patch flanked along it by two nearer surfaces gets their
            values there, while the background it belongs to lies beside it in the view.
        crack_parallax: forwarded to `forward_project`.
        solver: `SolverConfig` of the centre-view solve (2-D, multigrid by default).
        epi_solver: `SolverConfig` of the batched EPI solves (thin ``A × L`` grids, where a
            Jacobi preconditioner is much faster than the batched multigrid).
        fill_solver: `SolverConfig` of the hole-filling solves of off-cross-hair views.

    Raises:
        ValueError: on negative weights, non-positive ``ε``/``σ``, or unknown option names.

    References:
        Thesis Ch. 6, eqs 6.1–6.8; SPEC §4.
    """

    omega: Array = eqx.field(converter=_f32, default=150.0)
    a: Array = eqx.field(converter=_f32, default=3.0)
    lambda_e_max: Array = eqx.field(converter=_f32, default=2.0)
    offset_scale: Array = eqx.field(converter=_f32, default=1.0)
    centre_c: Array = eqx.field(converter=_f32, default=1.0)
    centre_eps: Array = eqx.field(converter=_f32, default=1e-3)
    conf_beta: Array = eqx.field(converter=_f32, default=10.0)
    wmf_sigma: Array = eqx.field(converter=_f32, default=0.05)
    epi_data_weight: Array = eqx.field(converter=_f32, default=15.0)
    epi_centre_weight: Array = eqx.field(converter=_f32, default=1000.0)
    epi_photo_sigma: Array = eqx.field(converter=_f32, default=0.1)
    epi_hole_weight: Array = eqx.field(converter=_f32, default=10.0)
    epi_min_confidence: Array = eqx.field(converter=_f32, default=0.1)
    epi_line_scale: Array = eqx.field(converter=_f32, default=1.0)
    epi_line_floor: Array = eqx.field(converter=_f32, default=0.1)
    epi_occlusion_tol: Array = eqx.field(converter=_f32, default=0.1)
    epi_c: Array = eqx.field(converter=_f32, default=0.1)
    epi_eps: Array = eqx.field(converter=_f32, default=1e-3)
    refine_jump: Array = eqx.field(converter=_f32, default=0.2)
    refine_margin: Array = eqx.field(converter=_f32, default=0.0)
    matte_jump: Array = eqx.field(converter=_f32, default=0.2)
    matte_min_separation: Array = eqx.field(converter=_f32, default=0.1)
    matte_impure_weight: Array = eqx.field(converter=_f32, default=0.05)
    select_min_change: Array = eqx.field(converter=_f32, default=0.0)
    select_margin: Array = eqx.field(converter=_f32, default=0.0)
    select_ssim: Array = eqx.field(converter=_f32, default=1.0)
    fill_c: Array = eqx.field(converter=_f32, default=1.0)
    fill_data_weight: Array = eqx.field(converter=_f32, default=1000.0)
    fill_hole_weight: Array = eqx.field(converter=_f32, default=1000.0)
    fill_min_confidence: Array = eqx.field(converter=_f32, default=0.5)
    upsample: int = eqx.field(static=True, default=1)
    colour_space: str = eqx.field(static=True, default="lab")
    sharpen: bool = eqx.field(static=True, default=True)
    wmf_radius: int = eqx.field(static=True, default=7)
    wmf_weight: str = eqx.field(static=True, default="exp")
    wmf_iterations: int = eqx.field(static=True, default=10)
    refine: bool = eqx.field(static=True, default=True)
    refine_radius: int = eqx.field(static=True, default=3)
    refine_iterations: int = eqx.field(static=True, default=12)
    refine_aggregate: int = eqx.field(static=True, default=2)
    matte: bool = eqx.field(static=True, default=True)
    matte_views: bool = eqx.field(static=True, default=True)
    matte_radius: int = eqx.field(static=True, default=2)
    matte_sigma: float = eqx.field(static=True, default=1.0)
    select_aggregate: int = eqx.field(static=True, default=3)
    hole_fill: str = eqx.field(static=True, default="solve")
    merge: str = eqx.field(static=True, default="photo")
    cross_hair_fill: bool = eqx.field(static=True, default=True)
    crack_parallax: float = eqx.field(static=True, default=0.5)
    solver: SolverConfig = SolverConfig()
    epi_solver: SolverConfig = SolverConfig(preconditioner="jacobi", max_iters=1000)
    fill_solver: SolverConfig = SolverConfig(preconditioner="jacobi", max_iters=1000)

    def __check_init__(self):
        nonneg = (
            "omega",
            "lambda_e_max",
            "centre_c",
            "conf_beta",
            "epi_data_weight",
            "epi_centre_weight",
            "epi_hole_weight",
            "epi_line_scale",
            "epi_line_floor",
            "epi_occlusion_tol",
            "epi_c",
            "fill_c",
            "fill_data_weight",
            "fill_hole_weight",
            "fill_min_confidence",
            "epi_min_confidence",
            "refine_jump",
            "refine_margin",
            "matte_jump",
            "matte_min_separation",
            "matte_impure_weight",
            "select_min_change",
            "select_margin",
            "select_ssim",
        )
        positive = ("centre_eps", "wmf_sigma", "epi_eps", "epi_photo_sigma")
        for name in nonneg + positive:
            v = _concrete(getattr(self, name))
            if v is None:
                continue
            if not np.all(np.isfinite(v)):
                raise ValueError(f"ReconstructConfig.{name} must be finite; got {v}")
            if name in positive and not np.all(v > 0):
                raise ValueError(f"ReconstructConfig.{name} must be > 0; got {v}")
            if name in nonneg and not np.all(v >= 0):
                raise ValueError(f"ReconstructConfig.{name} must be >= 0; got {v}")
        if self.upsample not in (1, 2):
            raise ValueError(f"ReconstructConfig.upsample must be 1 or 2; got {self.upsample}")
        if self.colour_space not in COLOUR_SPACES:
            raise ValueError(
                f"ReconstructConfig.colour_space must be one of {COLOUR_SPACES}; "
                f"got {self.colour_space!r}"
            )
        if self.wmf_weight not in WEIGHT_TYPES:
            raise ValueError(
                f"ReconstructConfig.wmf_weight must be one of {WEIGHT_TYPES}; "
                f"got {self.wmf_weight!r}"
            )
        if (
            int(self.refine_radius) < 1
            or int(self.refine_iterations) < 0
            or int(self.refine_aggregate) < 0
        ):
            raise ValueError(
                f"ReconstructConfig.refine_radius must be >= 1, refine_iterations and "
                f"refine_aggregate >= 0; got {self.refine_radius}, {self.refine_iterations}, "
                f"{self.refine_aggregate}"
            )
        if int(self.matte_radius) < 1 or not float(self.matte_sigma) > 0:
            raise ValueError(
                f"ReconstructConfig.matte_radius must be >= 1 and matte_sigma > 0; got "
                f"{self.matte_radius}, {self.matte_sigma}"
            )
        if int(self.select_aggregate) < 0:
            raise ValueError(
                f"ReconstructConfig.select_aggregate must be >= 0; got {self.select_aggregate}"
            )
        if int(self.wmf_radius) < 1 or int(self.wmf_iterations) < 1:
            raise ValueError(
                f"ReconstructConfig.wmf_radius and wmf_iterations must be >= 1; got "
                f"{self.wmf_radius}, {self.wmf_iterations}"
            )
        if self.hole_fill not in HOLE_FILLS:
            raise ValueError(
                f"ReconstructConfig.hole_fill must be one of {HOLE_FILLS}; got {self.hole_fill!r}"
            )
        if self.merge not in MERGES:
            raise ValueError(f"ReconstructConfig.merge must be one of {MERGES}; got {self.merge!r}")
        if not self.crack_parallax >= 0:
            raise ValueError(
                f"ReconstructConfig.crack_parallax must be >= 0; got {self.crack_parallax}"
            )
