"""`EdgeConfig`: every option of multi-view edge detection (thesis Ch. 4.1, SPEC §1)."""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

_SUBPIXEL = ("none", "parabolic", "variance")
_DIRECTIONS = ("both", "horizontal", "vertical")


def _f32(x) -> Array:
    return jnp.asarray(x, dtype=jnp.float32)


class EdgeConfig(eqx.Module):
    """Configuration of `detect_edges`.

    Values that change array shapes or control flow are static (changing them recompiles);
    thresholds, sigmas and weights are float32 array leaves (sweeping them does not recompile,
    and they can be differentiated or ``vmap``-ed where the stage is continuous).

    Attributes (static):
        n_filters: number of oriented Prewitt filters (one per candidate disparity).
        d_max: the bank covers disparities ``[-d_max, d_max]`` (pixels per view step). ``None``:
            taken from the light field's ``disparity_range`` (plus ``d_margin``), or
            ``d_max_fallback`` when the range is unknown.
        d_margin: added to the scene's largest absolute disparity when ``d_max`` is ``None``.
        d_max_fallback: bank half-range when neither ``d_max`` nor the scene range is known.
        directions: ``"both"`` (merge horizontal and vertical EPIs), ``"horizontal"`` or
            ``"vertical"``.
        blur_radius: half-width in pixels of the Gaussian pre-blur kernel.
        chunk: EPIs per chunk of the filter-bank convolution (bounds peak memory).
        refine_chunk: EPIs per chunk of the variance search.
        nms: non-maximum suppression across the line direction (Alg. 1). Without it every
            pixel is a candidate and line fitting (λ) alone thins them out.
        line_capacity: candidates / lines kept per EPI (fixed capacity; the strongest are kept
            and the rest counted in ``EdgeSet.n_dropped``). ``None``: the EPI width (every
            pixel of the centre row can hold a line, so nothing is ever dropped).
        subpixel: ``"none"`` (filter label only), ``"parabolic"`` (parabola through the
            responses of the neighbouring filters) or ``"variance"`` (parabolic, then a 1-D
            search minimising the colour variance along the EPI line on its less-varying side).
        variance_steps: disparities tried by the variance search.
        variance_radius: the variance search covers ``± variance_radius`` filter spacings
            (static: it fixes the resampling stencil) ...
        variance_min_shift: ... but at least enough to move the line by this many pixels in
            the outermost view (matters for few views, e.g. 3x3, where the bank's spacing is
            small compared with what the views can resolve).
        cubic: sample EPI lines with cubic (True) or linear interpolation in the variance search.
        variance_on_blurred: run the variance search on the pre-blurred EPIs (default; the
            interpolation along the lines is then less biased) instead of the raw ones.
        outliers: apply the outlier rejection of eqs 4.1–4.2 (`reject_outliers`). ``None``
            (default): only when the EPIs have at most ``outlier_auto_views`` views, where a
            line is supported by so few samples that wrong labels are common (HCI stillLife
            3x3: MSE×100 191 without, 24.5 with the agreement test). With 9 views it only
            removes correct points (the count test removes the isolated points of sparsely
            textured surfaces: HCI antinous 124.5 with it, 8.0 without).
        outlier_auto_views: the view count up to which ``outliers=None`` rejects outliers.
        outlier_test: ``"count"`` (eq 4.2: too few neighbours with the same disparity) or
            ``"agreement"`` (default: too small a fraction of the neighbours agree; see
            `reject_outliers`).
        outlier_window_frac: p, q = this fraction of the width / height (thesis 1/15).
        outlier_label_tol: lines whose filter labels differ by at most this count as "same
            disparity" in eq 4.1.
        multiscale: add lines from a 2x spatially downsampled light field that no fine line
            explains (4.1.4).
        gradient_alignment: drop lines whose EPI gradient is misaligned at too many samples
            (eq 4.3).
        alignment_c: k = EPI height / alignment_c aligned samples are required (thesis c = 4).
        drop_invisible: drop points that are not visible in the centre view (eq 4.4); when
            False they are kept and flagged ``visible = False``.
        entropy_search: entropy-based random search of both intercepts (eq 4.5).
        entropy_iters: iterations of the random search (thesis 10).
        entropy_bins: histogram bins of the per-line entropy.
        trilateral: joint spatial / disparity / colour filter of the sparse disparities (eq 4.6).
        trilateral_radius: half-width in pixels of the trilateral filter window (3 was more
            accurate than 5 or 10 on HCI backgammon and antinous, and is much cheaper).

    Attributes (array leaves):
        presmooth_sigma: Gaussian pre-blur of the views, pixels (SPEC: ≈ 0.85).
        edge_shift: offset in pixels of the two sides of each Prewitt filter from its line.
        aa_sigma: anti-aliasing of the filter lines (`prewitt_bank`; 0 = linear interpolation).
        lambda_frac: line-fitting suppression distance λ as a fraction of the EPI height
            (thesis 0.2; default 0: with the distinctiveness test below, suppressing the
            neighbours of confident lines only loses accurate points).
        min_confidence: candidates with a lower (modulated) confidence are ignored.
        min_ratio: drop points whose variance minimum is not distinct: colour variance at the
            ends of the search range over the variance at the best disparity (0 disables;
            2 kept more weakly textured points than 3 at equal accuracy downstream on HCI
            backgammon and antinous).
        min_local_std: drop candidates whose 3x3 EPI colour standard deviation (LAB / 100) is
            lower (flat regions).
        variance_offset: pixels to either side of the edge at which colour is sampled.
        max_colour_std: drop points whose best line still has a colour standard deviation
            along it (LAB / 100 units, less-varying side) above this; ``inf`` disables.
        outlier_tau: τ of eq 4.2. The thesis's 8e-5 belongs to its confidence scale; ours
            (response x 3x3 std in LAB / 100 units) is smaller, and 1e-5 was the most accurate
            setting that keeps most points (HCI backgammon and antinous).
        outlier_min_agreement: fraction of a point's window neighbours (same direction) that
            must share its disparity label with ``outlier_test = "agreement"``.
        multiscale_lambda_frac: a coarse line is dropped when both its intercepts are within
            this fraction of the EPI height of a fine line's (4.1.4; thesis λ = 0.2h).
        tau_f: gradient-alignment angle of eq 4.3, radians (thesis π/13).
        tau_v: centre-view visibility angle of eq 4.4, radians (thesis π/10).
        entropy_t, entropy_alpha: proposal scale ``alpha * t**j`` of the random search
            (thesis 0.88, 0.15).
        sigma_s, sigma_d, sigma_c: trilateral filter widths in pixels, disparity and LAB / 100
            (thesis 10, 0.1, 0.5).

    Raises:
        ValueError: on construction, for out-of-range values.

    References:
        Thesis Ch. 4.1 (Alg. 1, eqs 4.1–4.6); SPEC §1.
    """

    n_filters: int = eqx.field(static=True, default=61)
    d_max: float | None = eqx.field(static=True, default=None)
    d_margin: float = eqx.field(static=True, default=0.25)
    d_max_fallback: float = eqx.field(static=True, default=4.0)
    directions: str = eqx.field(static=True, default="both")
    blur_radius: int = eqx.field(static=True, default=3)
    chunk: int = eqx.field(static=True, default=64)
    refine_chunk: int = eqx.field(static=True, default=8)
    nms: bool = eqx.field(static=True, default=False)
    line_capacity: int | None = eqx.field(static=True, default=None)
    subpixel: str = eqx.field(static=True, default="variance")
    variance_steps: int = eqx.field(static=True, default=9)
    variance_radius: float = eqx.field(static=True, default=1.5)
    variance_min_shift: float = eqx.field(static=True, default=0.4)
    cubic: bool = eqx.field(static=True, default=True)
    variance_on_blurred: bool = eqx.field(static=True, default=True)
    outliers: bool | None = eqx.field(static=True, default=None)
    outlier_auto_views: int = eqx.field(static=True, default=5)
    outlier_test: str = eqx.field(static=True, default="agreement")
    outlier_window_frac: float = eqx.field(static=True, default=1.0 / 15.0)
    outlier_label_tol: int = eqx.field(static=True, default=1)
    multiscale: bool = eqx.field(static=True, default=False)
    gradient_alignment: bool = eqx.field(static=True, default=False)
    alignment_c: float = eqx.field(static=True, default=4.0)
    drop_invisible: bool = eqx.field(static=True, default=False)
    entropy_search: bool = eqx.field(static=True, default=False)
    entropy_iters: int = eqx.field(static=True, default=10)
    entropy_bins: int = eqx.field(static=True, default=16)
    trilateral: bool = eqx.field(static=True, default=True)
    trilateral_radius: int = eqx.field(static=True, default=3)

    presmooth_sigma: Float[Array, ""] = eqx.field(converter=_f32, default=0.85)
    edge_shift: Float[Array, ""] = eqx.field(converter=_f32, default=1.0)
    aa_sigma: Float[Array, ""] = eqx.field(converter=_f32, default=0.0)
    lambda_frac: Float[Array, ""] = eqx.field(converter=_f32, default=0.0)
    min_confidence: Float[Array, ""] = eqx.field(converter=_f32, default=1e-6)
    min_ratio: Float[Array, ""] = eqx.field(converter=_f32, default=2.0)
    min_local_std: Float[Array, ""] = eqx.field(converter=_f32, default=0.0)
    variance_offset: Float[Array, ""] = eqx.field(converter=_f32, default=1.5)
    max_colour_std: Float[Array, ""] = eqx.field(converter=_f32, default=float("inf"))
    outlier_tau: Float[Array, ""] = eqx.field(converter=_f32, default=1e-5)
    outlier_min_agreement: Float[Array, ""] = eqx.field(converter=_f32, default=0.15)
    multiscale_lambda_frac: Float[Array, ""] = eqx.field(converter=_f32, default=0.2)
    tau_f: Float[Array, ""] = eqx.field(converter=_f32, default=math.pi / 13)
    tau_v: Float[Array, ""] = eqx.field(converter=_f32, default=math.pi / 10)
    entropy_t: Float[Array, ""] = eqx.field(converter=_f32, default=0.88)
    entropy_alpha: Float[Array, ""] = eqx.field(converter=_f32, default=0.15)
    sigma_s: Float[Array, ""] = eqx.field(converter=_f32, default=10.0)
    sigma_d: Float[Array, ""] = eqx.field(converter=_f32, default=0.1)
    sigma_c: Float[Array, ""] = eqx.field(converter=_f32, default=0.5)

    def __check_init__(self):
        if not (isinstance(self.n_filters, int) and self.n_filters >= 3):
            raise ValueError(f"n_filters must be an int >= 3; got {self.n_filters!r}")
        if self.d_max is not None and not (math.isfinite(self.d_max) and self.d_max > 0):
            raise ValueError(f"d_max must be a positive finite float or None; got {self.d_max!r}")
        if not (self.d_max_fallback > 0 and self.d_margin >= 0):
            raise ValueError(
                f"need d_max_fallback > 0 and d_margin >= 0; got {self.d_max_fallback}, "
                f"{self.d_margin}"
            )
        if self.directions not in _DIRECTIONS:
            raise ValueError(f"directions must be one of {_DIRECTIONS}; got {self.directions!r}")
        if self.outlier_test not in ("count", "agreement"):
            raise ValueError(
                f"outlier_test must be 'count' or 'agreement'; got {self.outlier_test!r}"
            )
        if self.subpixel not in _SUBPIXEL:
            raise ValueError(f"subpixel must be one of {_SUBPIXEL}; got {self.subpixel!r}")
        if self.line_capacity is not None and not (
            isinstance(self.line_capacity, int) and self.line_capacity >= 1
        ):
            raise ValueError(
                f"line_capacity must be None or an int >= 1; got {self.line_capacity!r}"
            )
        for name in (
            "blur_radius",
            "chunk",
            "refine_chunk",
            "variance_steps",
            "entropy_iters",
            "entropy_bins",
            "trilateral_radius",
        ):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 1):
                raise ValueError(f"{name} must be an int >= 1; got {v!r}")
        if self.variance_steps < 3:
            raise ValueError(f"variance_steps must be >= 3; got {self.variance_steps}")
        if not (0 < self.outlier_window_frac <= 1):
            raise ValueError(
                f"outlier_window_frac must be in (0, 1]; got {self.outlier_window_frac}"
            )
        if self.outlier_label_tol < 0:
            raise ValueError(f"outlier_label_tol must be >= 0; got {self.outlier_label_tol}")
        if not self.alignment_c >= 1:
            raise ValueError(f"alignment_c must be >= 1; got {self.alignment_c}")
        if not (isinstance(self.variance_radius, (int, float)) and self.variance_radius > 0):
            raise ValueError(f"variance_radius must be a float > 0; got {self.variance_radius!r}")
        if not (isinstance(self.variance_min_shift, (int, float)) and self.variance_min_shift >= 0):
            raise ValueError(
                f"variance_min_shift must be a float >= 0; got {self.variance_min_shift!r}"
            )
        positive = (
            "presmooth_sigma",
            "edge_shift",
            "variance_offset",
            "sigma_s",
            "sigma_d",
            "sigma_c",
            "entropy_t",
            "max_colour_std",
        )
        nonneg = (
            "multiscale_lambda_frac",
            "aa_sigma",
            "min_ratio",
            "min_local_std",
            "lambda_frac",
            "min_confidence",
            "outlier_tau",
            "tau_f",
            "tau_v",
            "entropy_alpha",
        )
        try:
            vals = {n: float(getattr(self, n)) for n in positive + nonneg}
        except Exception:  # traced leaves (vmap over hyperparameters): nothing to check
            return
        for n in positive:
            if not vals[n] > 0:
                raise ValueError(f"{n} must be > 0; got {vals[n]}")
        for n in nonneg:
            if not vals[n] >= 0:
                raise ValueError(f"{n} must be >= 0; got {vals[n]}")
