"""`EdgeConfig`: every option of multi-view edge detection (thesis Ch. 4.1, SPEC §1), one
sub-config per step: `FilterConfig`, `LabelConfig`, `OutlierConfig`, `EdgeRefineConfig`."""

from __future__ import annotations

import math

import equinox as eqx
from jaxtyping import Array, Float

from .._fields import check_fields, hyperparameter, static

_SUBPIXEL = ("none", "parabolic", "variance")
_DIRECTIONS = ("both", "horizontal", "vertical")
#: Edge-detection strategies: ``"hard"`` (Alg. 1: argmax label, sub-pixel search) and
#: ``"soft"`` (the same points, labelled by a softmax over the filter responses).
STRATEGIES = ("hard", "soft")


class FilterConfig(eqx.Module):
    """EPI filtering with the oriented Prewitt bank (`EdgeConfig.filter`).

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

    Attributes (array leaves, all differentiable):
        presmooth_sigma: Gaussian pre-blur of the views, pixels (≈ 0.85).
        edge_shift: offset in pixels of the two sides of each Prewitt filter from its line.
        aa_sigma: anti-aliasing of the filter lines (`prewitt_bank`; 0 = linear
            interpolation). Differentiable where > 0 (0 switches to linear interpolation).

    Raises:
        TypeError, ValueError: on construction, for a value of the wrong type or out of
            range.

    References:
        Thesis Sec. 4.1.1 (Alg. 1: oriented Prewitt filters on the EPIs).
    """

    n_filters: int = static(61, lower=3)
    d_max: float | None = static(None, kind="float", lower=0.0, lower_open=True, upper=64.0)
    d_margin: float = static(0.25, lower=0.0, upper=64.0)
    d_max_fallback: float = static(4.0, lower=0.0, lower_open=True, upper=64.0)
    directions: str = static("both", choices=_DIRECTIONS)
    blur_radius: int = static(3, lower=1, upper=64)
    chunk: int = static(64, lower=1)

    presmooth_sigma: Float[Array, ""] = hyperparameter(
        0.85, differentiable=True, lower=0.0, lower_open=True
    )
    edge_shift: Float[Array, ""] = hyperparameter(
        1.0, differentiable=True, lower=0.0, lower_open=True
    )
    aa_sigma: Float[Array, ""] = hyperparameter(0.0, differentiable=True, lower=0.0)

    def __check_init__(self):
        check_fields(self)


class LabelConfig(eqx.Module):
    """Labels, line fitting and sub-pixel refinement (`EdgeConfig.label`).

    Attributes (static):
        strategy: ``"hard"`` (Alg. 1: each point's label is the best filter's disparity,
            refined by the parabolic and variance searches) or ``"soft"`` (the same points,
            labelled by the expected disparity under a softmax over the filter responses at
            temperature ``temperature`` times the pixel's largest response; see
            `soft_labels`). The hard labels are piecewise smooth in the hyperparameters (the
            argmax and the search's grid minimum jump); the soft labels are smooth.
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

    Attributes (array leaves; "differentiable" ones are smooth inputs of the chain, the
    others thresholds, piecewise constant, whose gradient is zero where it exists):
        temperature: softmax temperature of the ``"soft"`` strategy, relative to each
            pixel's largest filter response. Differentiable.
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
            Not declared differentiable: it moves the grid minimum of the variance search
            (piecewise), and the soft labels do not use it.
        max_colour_std: drop points whose best line still has a colour standard deviation
            along it (LAB / 100 units, less-varying side) above this; ``inf`` disables.

    Raises:
        TypeError, ValueError: on construction, for a value of the wrong type or out of
            range.

    References:
        Thesis Alg. 1 and Sec. 4.1.2 (labels, line fitting, sub-pixel refinement).
    """

    strategy: str = static("hard", choices=STRATEGIES)
    refine_chunk: int = static(8, lower=1)
    nms: bool = static(False)
    line_capacity: int | None = static(None, kind="int", lower=1)
    subpixel: str = static("variance", choices=_SUBPIXEL)
    variance_steps: int = static(9, lower=3, upper=1025)
    variance_radius: float = static(1.5, lower=0.0, lower_open=True)
    variance_min_shift: float = static(0.4, lower=0.0)
    cubic: bool = static(True)
    variance_on_blurred: bool = static(True)

    temperature: Float[Array, ""] = hyperparameter(
        0.1, differentiable=True, lower=0.0, lower_open=True
    )
    lambda_frac: Float[Array, ""] = hyperparameter(0.0, differentiable=False, lower=0.0)
    min_confidence: Float[Array, ""] = hyperparameter(1e-6, differentiable=False, lower=0.0)
    min_ratio: Float[Array, ""] = hyperparameter(2.0, differentiable=False, lower=0.0)
    min_local_std: Float[Array, ""] = hyperparameter(0.0, differentiable=False, lower=0.0)
    variance_offset: Float[Array, ""] = hyperparameter(
        1.5, differentiable=False, lower=0.0, lower_open=True
    )
    max_colour_std: Float[Array, ""] = hyperparameter(
        float("inf"), differentiable=False, lower=0.0, lower_open=True
    )

    def __check_init__(self):
        check_fields(self)


class OutlierConfig(eqx.Module):
    """Outlier rejection (`EdgeConfig.outliers`, `reject_outliers`).

    Attributes (static):
        enabled: apply the outlier rejection of eqs 4.1–4.2. ``None`` (default): only when
            the EPIs have at most ``auto_views`` views, where a line is supported by so few
            samples that wrong labels are common (HCI stillLife 3x3: MSE×100 191 without,
            24.5 with the agreement test). With 9 views it only removes correct points (the
            count test removes the isolated points of sparsely textured surfaces: HCI
            antinous 124.5 with it, 8.0 without).
        auto_views: the view count up to which ``enabled=None`` rejects outliers.
        test: ``"count"`` (eq 4.2: too few neighbours with the same disparity) or
            ``"agreement"`` (default: too small a fraction of the neighbours agree; see
            `reject_outliers`).
        window_frac: p, q = this fraction of the width / height (thesis 1/15).
        label_tol: lines whose filter labels differ by at most this count as "same
            disparity" in eq 4.1.

    Attributes (array leaves, thresholds: piecewise constant, zero gradient where it exists):
        tau: τ of eq 4.2. The thesis's 8e-5 belongs to its confidence scale; ours
            (response x 3x3 std in LAB / 100 units) is smaller, and 1e-5 was the most accurate
            setting that keeps most points (HCI backgammon and antinous).
        min_agreement: fraction of a point's window neighbours (same direction) that must
            share its disparity label with ``test = "agreement"``.

    Raises:
        TypeError, ValueError: on construction, for a value of the wrong type or out of
            range.

    References:
        Thesis Ch. 4.1, eqs 4.1–4.2.
    """

    enabled: bool | None = static(None, kind="bool")
    auto_views: int = static(5, lower=0)
    test: str = static("agreement", choices=("count", "agreement"))
    window_frac: float = static(1.0 / 15.0, lower=0.0, lower_open=True, upper=1.0)
    label_tol: int = static(1, lower=0)

    tau: Float[Array, ""] = hyperparameter(1e-5, differentiable=False, lower=0.0)
    min_agreement: Float[Array, ""] = hyperparameter(0.15, differentiable=False, lower=0.0)

    def __check_init__(self):
        check_fields(self)


class EdgeRefineConfig(eqx.Module):
    """Optional refinements of the edge model (`EdgeConfig.refine`): multi-scale lines,
    gradient alignment, centre-view visibility, entropy search, trilateral filter.

    Attributes (static):
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

    Attributes (array leaves; "differentiable" ones are smooth inputs of the chain, the
    others thresholds, piecewise constant, whose gradient is zero where it exists):
        multiscale_lambda_frac: a coarse line is dropped when both its intercepts are within
            this fraction of the EPI height of a fine line's (4.1.4; thesis λ = 0.2h).
        tau_f: gradient-alignment angle of eq 4.3, radians (thesis π/13).
        tau_v: centre-view visibility angle of eq 4.4, radians (thesis π/10).
        entropy_t, entropy_alpha: proposal scale ``alpha * t**j`` of the random search
            (thesis 0.88, 0.15).
        sigma_s, sigma_d, sigma_c: trilateral filter widths in pixels, disparity (pixels per
            view step) and LAB / 100 (thesis 10, 0.1, 0.5; ``sigma_d`` 0.035 by
            leave-one-scene-out over the synthetic and HCI scenes, docs/ACCURACY.md).
            Differentiable.

    Raises:
        TypeError, ValueError: on construction, for a value of the wrong type or out of
            range.

    References:
        Thesis Sec. 4.1.3–4.1.6, eqs 4.3–4.6.
    """

    multiscale: bool = static(False)
    gradient_alignment: bool = static(False)
    alignment_c: float = static(4.0, lower=1.0)
    drop_invisible: bool = static(False)
    entropy_search: bool = static(False)
    entropy_iters: int = static(10, lower=1, upper=1000)
    entropy_bins: int = static(16, lower=1, upper=4096)
    trilateral: bool = static(True)
    trilateral_radius: int = static(3, lower=1, upper=64)

    multiscale_lambda_frac: Float[Array, ""] = hyperparameter(0.2, differentiable=False, lower=0.0)
    tau_f: Float[Array, ""] = hyperparameter(math.pi / 13, differentiable=False, lower=0.0)
    tau_v: Float[Array, ""] = hyperparameter(math.pi / 10, differentiable=False, lower=0.0)
    entropy_t: Float[Array, ""] = hyperparameter(
        0.88, differentiable=False, lower=0.0, lower_open=True
    )
    entropy_alpha: Float[Array, ""] = hyperparameter(0.15, differentiable=False, lower=0.0)
    sigma_s: Float[Array, ""] = hyperparameter(
        10.0, differentiable=True, lower=0.0, lower_open=True
    )
    sigma_d: Float[Array, ""] = hyperparameter(
        0.035, differentiable=True, lower=0.0, lower_open=True
    )
    sigma_c: Float[Array, ""] = hyperparameter(0.5, differentiable=True, lower=0.0, lower_open=True)

    def __check_init__(self):
        check_fields(self)


class EdgeConfig(eqx.Module):
    """Configuration of `detect_edges`, one sub-config per step of thesis Ch. 4.1.

    Values that change array shapes or control flow are static (changing them recompiles);
    thresholds, sigmas and weights are float32 array leaves (sweeping them does not recompile,
    and they can be differentiated or ``vmap``-ed where the stage is continuous).

    Attributes:
        filter: `FilterConfig`: EPI filtering with the oriented Prewitt bank (Sec. 4.1.1).
        label: `LabelConfig`: labels, line fitting, sub-pixel refinement (Alg. 1,
            Sec. 4.1.2).
        outliers: `OutlierConfig`: outlier rejection (eqs 4.1–4.2).
        refine: `EdgeRefineConfig`: optional refinements (Sec. 4.1.3–4.1.6, eqs 4.3–4.6).

    Raises:
        TypeError: on construction, for a sub-config of the wrong type (the sub-configs
            check their own fields when they are built).

    References:
        Thesis Ch. 4.1 (Alg. 1, eqs 4.1–4.6).
    """

    filter: FilterConfig = FilterConfig()
    label: LabelConfig = LabelConfig()
    outliers: OutlierConfig = OutlierConfig()
    refine: EdgeRefineConfig = EdgeRefineConfig()

    def __check_init__(self):
        check_fields(self)
