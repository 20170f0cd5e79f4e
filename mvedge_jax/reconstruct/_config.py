"""`ReconstructConfig`: every option of the smooth 4D reconstruction (thesis Ch. 6), one
sub-config per step: `CentreConfig`, `SeedConfig`, `SharpenConfig`, `SelectConfig`, `EpiConfig`,
`FillConfig`."""

from __future__ import annotations

import equinox as eqx
from jaxtyping import Array

from .._fields import check_fields, hyperparameter, static
from ..solve import SolverConfig
from ._wmf import WEIGHT_TYPES

COLOUR_SPACES = ("lab", "rgb")
MATTE_COLOURS = (*COLOUR_SPACES, "linear")  # every guide of `colour_guide`
HOLE_FILLS = ("solve", "background")
FILL_CHOICES = ("colour", "farthest")
HOLE_VALUES = ("farther", "fill")
MERGES = ("photo", "mean")
#: Filters of the sharpening step: the weighted median (thesis) and its smooth surrogate.
SHARPEN_FILTERS = ("median", "mean")


class CentreConfig(eqx.Module):
    """Centre-view diffusion of the edge labels (`ReconstructConfig.centre`).

    Attributes:
        omega: ``ω`` of the centre data weight ``ω · exp(a · λ_e)`` (eq 6.3; thesis 150).
        a: exponent ``a`` of eq 6.3 (thesis 3).
        lambda_e_max: ``λ_e`` is clipped to ``[0, lambda_e_max]`` before the exponential.
        offset_scale: labels are splatted at ``p + offset_scale · n`` (``n`` the surface
            vector, pixels).
        c: numerator of the centre smoothness ``c / (|∇I| + ε)``.
        eps: ``ε`` of the centre smoothness, in guide units (see
            ``ReconstructConfig.colour_space``). Small against the guide's quantisation
            step (one 8-bit level moves the CIELAB / 100 guide by 0.0005 or more), so that
            it only acts where neighbouring colours are equal: there the weight is
            ``c / ε``, and a uniform region diffuses as one (docs/ACCURACY.md, "Colour-edge
            ε"). The centre solve takes more iterations as ``ε`` shrinks.
        conf_beta: depth-edge confidence attenuation: smoothness across an edge is divided by
            ``1 + conf_beta · conf`` (``conf`` the larger confidence of the two pixels).
        splat_uniform: (threshold) a label's splat is tested where the pixel 2 px across
            its edge lies on a region whose neighbouring colours differ by less than this
            (guide units; `uniform_window`); 0 turns the test off (`splat_mask`).
        splat_colour: (threshold) there, a splat corner whose colour differs from the
            label's own surface by more than this (Euclidean, guide units) gets no weight.
        splat_side_ratio: (threshold, dimensionless) such a corner (colour off the label's
            own surface by more than ``splat_colour``) also gets no weight, wherever the
            pixel 2 px across the edge lies, if its colour distance to that pixel is below
            this times its distance to the own surface's colour: the corner shows the other
            side (`splat_mask`). 0 (the default) turns the test off; 0.1 takes the
            synthetic textureless scenes' all-views MSE×100 down 3–9× and moves the
            textured scenes by −1 to +1.5 % (docs/ACCURACY.md, "Splat corners that show the
            other side").
        upsample: (static) solve the centre problem on an ``upsample×`` grid (1 or 2) and
            average back (sub-pixel label placement).
        solver: `SolverConfig` of the centre-view solve (2-D, multigrid by default).

    The array fields are differentiable except the three thresholds.

    Raises:
        TypeError, ValueError: on construction, for a value of the wrong type or out of
            range.

    References:
        Thesis Ch. 6, eqs 6.1–6.3.
    """

    omega: Array = hyperparameter(150.0, differentiable=True, lower=0.0)
    a: Array = hyperparameter(3.0, differentiable=True)
    lambda_e_max: Array = hyperparameter(2.0, differentiable=True, lower=0.0)
    offset_scale: Array = hyperparameter(1.0, differentiable=True)
    c: Array = hyperparameter(1.0, differentiable=True, lower=0.0)
    eps: Array = hyperparameter(3e-6, differentiable=True, lower=0.0, lower_open=True)
    conf_beta: Array = hyperparameter(10.0, differentiable=True, lower=0.0)
    splat_uniform: Array = hyperparameter(0.02, differentiable=False, lower=0.0)
    splat_colour: Array = hyperparameter(0.05, differentiable=False, lower=0.0)
    splat_side_ratio: Array = hyperparameter(0.0, differentiable=False, lower=0.0)
    upsample: int = static(1, lower=1, upper=2)
    solver: SolverConfig = SolverConfig()

    def __check_init__(self):
        check_fields(self)


class SharpenConfig(eqx.Module):
    """Sharpening of the centre map and boundary snapping / matting
    (`ReconstructConfig.sharpen`).

    Attributes (array leaves; "threshold" ones only switch discrete decisions: the chain is
    piecewise constant in them, zero gradient where it exists):
        wmf_sigma: range parameter of the weighted median filter (guide units, RGB [0, 1]).
            The median only selects a sample, so the chain is piecewise constant in it;
            with ``filter = "mean"`` it is differentiable.
        refine_jump: (threshold) photo-consistent boundary snapping (`photo_refine`) acts where the
            disparity range of the window exceeds this (pixels per view step).
        refine_margin: (threshold) colour-cost advantage a candidate needs over the current value.
        refine_near_weight: (threshold) weight of the cross-hair views one step from the
            centre in the snapping's colour cost (`photo_refine`'s ``near_weight``; the
            others weigh 1).
        matte_jump: (threshold) disparity range of a window that marks a depth discontinuity for
            `boundary_matte` (pixels per view step).
        matte_view_jump: (threshold) the same for the maps of the other views
            (``matte_views``), which come from the projection of the sharpened centre map.
        matte_view_tolerance: (threshold) `observed_background`'s ``tolerance``: a sample
            of another view counts as the background where that view's map spans less than
            this over the 3×3 window there and lies within this of the background disparity
            (pixels per view step).
        matte_min_separation: (threshold) `boundary_matte` decides only where the foreground and
            background colours differ by at least this (in the units of ``matte_colour``:
            linear light in [0, 1] by default).
        matte_impure_weight: (threshold) weight of window pixels on a discontinuity in the colour
            means.
        matte_snap: (threshold) `boundary_matte`'s ``snap`` for the centre map: a decided
            pixel whose value differs from its side's mean disparity by more than this
            fraction of the two sides' difference takes that mean (dimensionless; a large
            value: a pixel on its side keeps its value).
        matte_view_snap: (threshold) the same for the maps of the other views
            (``matte_views``); 0: every pixel the views' matte decides takes its side's mean.
        matte_max_residual: (threshold) `boundary_matte` decides only where the pixel's
            colour lies within this squared distance of the line through the foreground and
            background colours, relative to their squared distance (its ``max_residual``;
            dimensionless; a large value switches the test off).
        matte_phase: (threshold) `near_surface_colours`' ``phase`` for the centre map's
            matte (``matte_other_steps``): a sample of another view weighs
            ``max(0, 1 − φ / matte_phase)``, ``φ`` the distance (pixels) between its pixel
            and the position of the pixel's nearest surface in that view.
        matte_align_tolerance: (threshold) `boundary_matte`'s ``align_tolerance`` for the
            centre map's matte: the other views count where the window's largest disparity
            lies within this fraction of the two sides' difference of the foreground side's
            mean (dimensionless).
        matte_soft: (threshold) `boundary_matte`'s ``soft`` for the centre map: a decided
            pixel whose mixture fraction ``α`` lies within ``matte_soft / 2`` of 1/2 takes
            the blend ``p V_F + (1 − p) V_B`` of the values it would take on either side,
            ``p = 1/2 + (α − 1/2) / matte_soft`` (dimensionless): the value of least expected
            squared error where the colours leave the side uncertain. Lowers the MSE and
            raises the bad pixels at a tight threshold (the blended values lie on neither
            surface). 0: every decided pixel takes one side's value.
        matte_view_soft: (threshold) the same for the maps of the other views
            (``matte_views``); 0.1 by default (chosen by leave-one-scene-out; the centre
            map's stays 0: docs/ACCURACY.md, "Blended values where the matte is unsure").
        sweep_search: largest change the plane sweep (`photo_sweep`) may make, pixels per
            view step. Smooth where the chosen hypothesis does not change (the hypotheses
            scale with it).
        sweep_margin: (threshold) relative cost advantage over the pixel's own value that a
            plane-sweep move needs (`photo_sweep`'s ``margin``; 0 = none).
        sweep_support_jump: (threshold) depth-aware support of the sweep's cost
            aggregation: window pixels whose disparity differs from the pixel's by more
            than this (pixels per view step) do not count (`photo_sweep`'s
            ``support_jump``; a value above the scene's disparity range switches it off).
        shading_threshold: (threshold) largest colour difference (L1 over the channels) of
            a pixel that enters the shading estimate (`shading_bias`'s ``threshold``).
        shading_floor: (threshold) soft threshold of the shading estimate, colour units per
            channel (`shading_bias`'s ``floor``).
        shading_jump: (threshold) pixels within ``shading_edge_radius`` of a 7×7 window whose
            disparity range exceeds this (pixels per view step) stay out of the shading
            estimate.

    Attributes (static):
        enabled: apply the weighted median filter to the centre disparity (Sec. 6.1).
        filter: ``"median"`` (the weighted median filter of Sec. 6.1, which selects
            one sample of the window per pixel: piecewise smooth in the disparities, piecewise
            constant in ``wmf_sigma``) or ``"mean"`` (the weighted mean with the same weights:
            its smooth surrogate, used to differentiate through the sharpening).
        wmf_radius: weighted-median window radius (thesis 7).
        wmf_weight: weighted-median weight type (see `weighted_median_filter`).
        wmf_iterations: bisection steps of the weighted median.
        wmf_slope_baseline: first-order (slanted-surface) filtering: each window sample ``q``
            enters the filter as ``d_q + ∇d_q · (p − q)``, its own surface extrapolated to the
            centre pixel ``p``, with ``∇d`` the `disparity_slopes` of the filter's input
            (minmod of differences over this many pixels, so no slope spans a
            discontinuity). A window on one slanted plane then votes for the
            plane's value at ``p`` whatever the colour weights, where the plain median returns
            the value of whichever sample the weights favour (up to ``wmf_radius`` pixels
            of slope away). 0 = the plain filter of the samples (the thesis).
        wmf_slope_max: largest slope magnitude used by that extrapolation (pixels per view
            step per pixel); steeper estimates are clipped (the blur across a discontinuity
            is not a surface). The sharpened map stays differentiable in the disparities
            (through the extrapolated samples); these two fields are static options.
        refine: snap the centre disparity near depth discontinuities to the photo-consistent
            side (occlusion-aware multi-view colour test, `photo_refine`) before the weighted
            median.
        refine_radius: window radius of that test (candidates: window min and max).
        refine_iterations: passes of the centre-view refinement.
        refine_aggregate: radius of the colour-weighted cost aggregation of that test.
        sweep_steps: after the snapping and the matte and before the weighted median,
            correct every centre pixel by a local plane sweep of this many hypotheses
            (`photo_sweep` against the cross-hair views; odd, ≥ 3; 0 = off; not in the
            thesis).
        sweep_ssim: weight of the SSIM dissimilarity in the sweep's colour cost (0: colour
            L1 only, and the SSIM term is not computed).
        sweep_aggregate: radius of the colour-weighted cost aggregation of the sweep.
        sweep_min_offset: the sweep uses the cross-hair views at least this many view steps
            from the centre (all of them when the light field has no such view): the
            nearest views add little disparity resolution for their cost.
        shading_sigma: compensate the view-dependent shading of the cross-hair views in the
            snapping's and the plane sweep's colour costs: `shading_bias` of each view,
            estimated once with the centre map entering the sharpening, smoothed with this
            standard deviation (pixels), is subtracted from the warped view (not in the
            thesis). 0 = off.
        shading_edge_radius: distance (chessboard, pixels) from a ``shading_jump`` edge within
            which pixels stay out of the shading estimate.
        matte: after the snapping and before the weighted median, put every pixel on a depth
            discontinuity of the centre map on the side its colour mixture says
            (`boundary_matte`; not in the thesis).
        matte_views: apply `boundary_matte` to every other view's final map too (reprojected
            boundaries are only pixel-accurate); ~20 ms per 512² view, ~12 ms more with
            ``matte_view_steps > 0``.
        matte_view_steps: the views' matte takes its background colour from the views up
            to this many steps away along the grid's axes that see the background surface
            at the pixel unoccluded (`observed_background`), where one does; elsewhere, and
            at 0, from the window mean (not in the thesis).
        matte_other_steps: the centre map's matte takes the colour mixture of every pixel
            from the cross-hair views up to this many steps away too, sampled at the
            pixel's nearest surface (`boundary_matte`'s ``others``, `near_surface_colours`;
            not in the thesis); 0: from the centre view alone.
        matte_foreground_fit, matte_background_fit: `boundary_matte`'s ``foreground_fit``
            and ``background_fit`` for the centre map's matte: the side's colour at the
            pixel is a linear fit of its colours over the window, whose gradient is held
            back by a ridge of the inverse of this (1 / (weight units × pixels²)); 0: their
            mean (not in the thesis).
        matte_view_foreground_fit, matte_view_background_fit: the same for the maps of the
            other views (``matte_views``).
        matte_view_split: `boundary_matte`'s ``split_background`` for the maps of the
            other views (``matte_views``): where a window's background side holds two
            surfaces of distinct colours (a strip of far background between a near object
            and a nearer floor, seen past the centre view's occlusions), a pixel on it is
            matted against the one whose two-colour model explains its colour best and
            takes that one's disparity, instead of the two surfaces' mixed means (not in
            the thesis). Needs ``matte_view_background_fit`` at 0.
        matte_radius: window radius of `boundary_matte`.
        matte_sigma: distance scale of its colour means, pixels.
        matte_colour: the colours of its two-colour mixture model: ``"linear"`` (sRGB
            decoded to linear light, where a pixel on an occlusion edge is the area-weighted
            mean of the two surfaces' colours, as in a camera or an anti-aliased render),
            ``"lab"`` (CIELAB / 100) or ``"rgb"`` (the encoded values). Its
            ``matte_min_separation`` is in the same units.

    Raises:
        TypeError, ValueError: on construction, for a value of the wrong type or out of
            range (e.g. an unknown filter name).

    References:
        Thesis Sec. 6.1 (weighted median filter); the snapping and the matte are not in the
        thesis.
    """

    wmf_sigma: Array = hyperparameter(0.05, differentiable=True, lower=0.0, lower_open=True)
    refine_jump: Array = hyperparameter(0.2, differentiable=False, lower=0.0)
    refine_margin: Array = hyperparameter(0.0, differentiable=False, lower=0.0)
    refine_near_weight: Array = hyperparameter(2.0, differentiable=False, lower=0.0)
    matte_jump: Array = hyperparameter(0.2, differentiable=False, lower=0.0)
    matte_view_jump: Array = hyperparameter(0.5, differentiable=False, lower=0.0)
    matte_view_tolerance: Array = hyperparameter(0.5, differentiable=False, lower=0.0)
    matte_min_separation: Array = hyperparameter(0.15, differentiable=False, lower=0.0)
    matte_impure_weight: Array = hyperparameter(0.05, differentiable=False, lower=0.0)
    matte_snap: Array = hyperparameter(1e9, differentiable=False, lower=0.0)
    matte_view_snap: Array = hyperparameter(0.0, differentiable=False, lower=0.0)
    matte_max_residual: Array = hyperparameter(1e9, differentiable=False, lower=0.0)
    matte_phase: Array = hyperparameter(0.5, differentiable=False, lower=0.0, lower_open=True)
    matte_align_tolerance: Array = hyperparameter(0.1, differentiable=False, lower=0.0)
    matte_soft: Array = hyperparameter(0.0, differentiable=False, lower=0.0)
    matte_view_soft: Array = hyperparameter(0.1, differentiable=False, lower=0.0)
    sweep_search: Array = hyperparameter(0.3, differentiable=True, lower=0.0, lower_open=True)
    sweep_margin: Array = hyperparameter(0.0, differentiable=False, lower=0.0, upper=1.0)
    sweep_support_jump: Array = hyperparameter(0.1, differentiable=False, lower=0.0)
    shading_threshold: Array = hyperparameter(0.015, differentiable=False, lower=0.0)
    shading_floor: Array = hyperparameter(1e-4, differentiable=False, lower=0.0)
    shading_jump: Array = hyperparameter(0.5, differentiable=False, lower=0.0)
    enabled: bool = static(True)
    filter: str = static("median", choices=SHARPEN_FILTERS)
    wmf_radius: int = static(7, lower=1, upper=64)
    wmf_weight: str = static("exp", choices=WEIGHT_TYPES)
    wmf_iterations: int = static(10, lower=1, upper=64)
    wmf_slope_baseline: int = static(12, lower=0, upper=64)
    wmf_slope_max: float = static(0.05, lower=0.0)
    refine: bool = static(True)
    refine_radius: int = static(3, lower=1, upper=64)
    refine_iterations: int = static(12, lower=0, upper=1000)
    refine_aggregate: int = static(2, lower=0, upper=64)
    sweep_steps: int = static(9, lower=0, upper=101)
    sweep_ssim: float = static(0.0, lower=0.0)
    sweep_aggregate: int = static(4, lower=0, upper=64)
    sweep_min_offset: int = static(2, lower=1, upper=64)
    shading_sigma: float = static(16.0, lower=0.0)
    shading_edge_radius: int = static(4, lower=0, upper=64)
    matte: bool = static(True)
    matte_views: bool = static(True)
    matte_view_steps: int = static(4, lower=0, upper=64)
    matte_other_steps: int = static(4, lower=0, upper=64)
    matte_foreground_fit: float = static(0.0, lower=0.0)
    matte_background_fit: float = static(0.0, lower=0.0)
    matte_view_foreground_fit: float = static(1.0, lower=0.0)
    matte_view_background_fit: float = static(0.0, lower=0.0)
    matte_view_split: bool = static(True)
    matte_radius: int = static(2, lower=1, upper=64)
    matte_sigma: float = static(1.0, lower=0.0, lower_open=True)
    matte_colour: str = static("linear", choices=MATTE_COLOURS)

    def __check_init__(self):
        check_fields(self)
        if self.sweep_steps != 0 and (self.sweep_steps < 3 or self.sweep_steps % 2 == 0):
            raise ValueError(
                f"SharpenConfig.sweep_steps must be 0 (off) or an odd integer >= 3; "
                f"got {self.sweep_steps}"
            )
        if self.matte_view_split and self.matte_view_background_fit > 0:
            raise ValueError(
                "SharpenConfig.matte_view_split splits the background side's mean colours; "
                "it needs matte_view_background_fit = 0 (got "
                f"{self.matte_view_background_fit}); set matte_view_split = false to fit"
            )


class SeedConfig(eqx.Module):
    """Disparity samples of the centre diffusion where no edge label is near
    (`ReconstructConfig.seeds`, `centre_seeds`, `photo_seeds`; not in the thesis).

    Attributes:
        weight: data weight of a sample in the centre diffusion (eq 6.1's data term; an
            edge label weighs ``centre.omega · exp(a · λ_e)`` ≥ 150).
        ratio: (threshold) largest best / second-best photo-cost ratio of a sample.
        min_contrast: (threshold) smallest second-best minus best cost of a sample (colour
            units, L1 summed over the channels); rejects uniform colour, whose costs are
            all equal.
        exclusion: (threshold) half-width around the best hypothesis left out of the
            second-best cost, pixels per view step.
        margin: the hypotheses span the edge labels' disparity range widened by
            this on both sides, pixels per view step.
        behind_jump: (threshold) within ``min_distance`` of a label, a pixel still gets a
            sample where its value is farther (smaller) than every label within that
            distance by more than this, pixels per view step: a surface seen through a gap
            between nearer ones, such as a strip of the far wall between an object and the
            floor, whose own texture gave no edge label; 1e9: off.
        steps: (static) number of fronto-parallel hypotheses; 0 turns the samples off.
        scale: (static) reduction factor of the sweep.
        aggregate: (static) radius of the colour-weighted cost aggregation at the reduced
            resolution.
        min_distance: (static) pixels (chessboard) from the nearest edge label below which
            no sample is made.

    Raises:
        TypeError, ValueError: on construction, for a value of the wrong type or out of
            range, or ``steps`` of 1 or 2.

    References:
        Thesis Sec. 8.1.1 (future research: adding samples to the edge set); eq 7.15
        (warping error).
    """

    weight: Array = hyperparameter(30.0, differentiable=True, lower=0.0)
    ratio: Array = hyperparameter(0.6, differentiable=False, lower=0.0, upper=1.0)
    min_contrast: Array = hyperparameter(2e-4, differentiable=False, lower=0.0)
    exclusion: Array = hyperparameter(0.8, differentiable=False, lower=0.0)
    margin: Array = hyperparameter(0.25, differentiable=True, lower=0.0)
    behind_jump: Array = hyperparameter(1.0, differentiable=False, lower=0.0)
    steps: int = static(49, lower=0, upper=401)
    scale: int = static(2, lower=1, upper=8)
    aggregate: int = static(3, lower=0, upper=64)
    min_distance: int = static(10, lower=0, upper=256)

    def __check_init__(self):
        check_fields(self)
        if self.steps in (1, 2):
            raise ValueError(f"SeedConfig.steps must be 0 (off) or >= 3; got {self.steps}")


class SelectConfig(eqx.Module):
    """Merge of an optimised centre map by `select_centre` (`ReconstructConfig.select`).

    Attributes:
        min_change: (threshold) `select_centre` tests a candidate centre map only where it
            differs from the incumbent by more than this (pixels per view step).
        margin: (threshold) colour-cost advantage the candidate needs there (L1 colour
            units).
        ssim: (threshold) weight of the SSIM dissimilarity in the cost of `select_centre`
            (`photo_cost`'s ``ssim``; 0 = colour L1 only). 1 weighs it like eq 7.16, whose terms the
            Ch. 7 optimisation minimises. On antinous the L1 alone cannot tell
            disparities ±0.05 apart on the faint texture of the floor and background (the L1 error
            of the GT and of GT − 0.05 is equal there; the SSIM term is 5% higher), and the merge
            missed half the pixels the optimisation had fixed.
        aggregate: (static) radius of the colour-weighted cost aggregation of `select_centre`.

    Raises:
        TypeError, ValueError: on construction, for a value of the wrong type or out of
            range.

    References:
        Thesis Ch. 7 (eq 7.16); the merge itself is not in the thesis.
    """

    min_change: Array = hyperparameter(0.0, differentiable=False, lower=0.0)
    margin: Array = hyperparameter(0.0, differentiable=False, lower=0.0)
    ssim: Array = hyperparameter(1.0, differentiable=False, lower=0.0)
    aggregate: int = static(3, lower=0, upper=64)

    def __check_init__(self):
        check_fields(self)


class EpiConfig(eqx.Module):
    """Cross-hair projection and angular inpainting of the EPIs (`ReconstructConfig.epi`).

    Attributes (array leaves; "threshold" ones only switch discrete decisions, the others
    are differentiable):
        data_weight: data weight on reprojected pixels (eq 6.8; thesis 15).
        centre_weight: data weight of the centre view's row of every EPI (the estimated
            map itself; large = the centre view keeps its estimate).
        photo_sigma: colour scale (RGB) of the photometric confidence of reprojected
            pixels (`photometric_confidence`), which multiplies ``data_weight``; large =
            off.
        hole_weight: weight, in the angular inpainting, of the background prior in
            reprojection holes (disoccluded pixels take the farther side along the EPI's
            spatial axis). On the synthetic default scene (9x9x160², with the other defaults)
            3, 10 and 30 give a worst per-view MSE×100 within 0.02 of each other; 1 is worse.
        min_confidence: (threshold) a reprojected pixel (off the centre row) whose photometric
            confidence is at most this counts as a hole in the angular inpainting: a value whose
            colour does not match was carried across a disocclusion (a foreground value spilled onto
            the background). 0 = every landed pixel is data (the thesis).
        line_scale: multiplier of ``λ_e`` on EPI-line pixels (eq 6.8; thesis 1).
        line_floor: minimum line weight (so that lines with ``λ_e ≈ 0`` still guide).
        occlusion_tol: (threshold) an EPI-line pixel is dropped where the reprojected disparity
            is larger (nearer) than the line's by more than this (the line is occluded there).
        c: numerator ``c`` of the EPI smoothness (eq 6.7; thesis 0.1).
        eps: ``ε`` of eq 6.7, guide units.
        visibility_tol: (threshold) disparity margin of `contradicted_by_centre` in the
            ``visibility_fill`` test (pixels per view step).
        colour_margin: (threshold) `colour_fill`'s ``margin`` for the 2-D fill with
            ``fill_choice = "colour"`` (CIELAB / 100 or RGB, as ``colour_space``; L1 over the
            channels): the colour-nearest of the four candidates replaces the farthest only
            where its colour is closer by more than this.
        frame_margin: (threshold) with ``cross_hair_fill``, `fill_beyond_frame`'s
            ``margin`` (pixels per view step) after the fill of the holes: a hole in a run
            of holes along the view's row (centre row) or column (centre column) that
            reaches the frame's border takes the run's farthest value where that value's
            surface point lies beyond the centre view's frame and is farther than the
            hole's own value by more than this (the strip along the border where a far
            surface enters the view beside a nearer one); 1e9: off.

    Attributes (static):
        cross_hair_fill: in every cross-hair view but the centre, the holes of the
            projection (as counted by ``min_confidence``) take a 2-D fill of the view from
            the nearest valid values left, right, above and below (``fill_choice``; with
            ``hole_value = "farther"`` the inpainted value where that is farther). The EPI
            inpainting sees one image row or column only: a disoccluded patch flanked along
            it by two nearer surfaces gets their values there, while the background it
            belongs to lies beside it in the view.
        fill_choice: which of those four nearest valid values the 2-D fill takes:
            ``"colour"``, the one whose pixel's colour in the view is closest to the hole
            pixel's (`colour_fill`; ties: the farthest), or ``"farthest"``, the smallest
            (`background_fill`). Where a nearer surface hides part of a mid-depth one in
            the centre view, the farthest is the background beyond the mid-depth surface;
            the colour finds the surface the hole shows (synthetic wide variant: all views
            MSE×100 15.0 → 10.5, worst view 27.8 → 16.4; not in the thesis).
        hole_value: what those holes take: ``"fill"``, the 2-D fill alone, or
            ``"farther"``, the farther of the inpainted value and the 2-D fill. The
            inpainting interpolates across the hole between the values at its ends, so a
            disocclusion flanked by a far and a mid-depth surface gets values between the
            two, which no surface has; the farther of such a blend and the 2-D fill is the
            blend wherever the fill found the mid-depth surface (synthetic scenes, all
            views MSE×100: wide 2.50 → 2.26, thin 1.02 → 0.93 with ``"fill"``; not in the
            thesis).
        visibility_fill: with ``cross_hair_fill``, a hole that nothing was projected to
            keeps that value only where the centre view does not contradict it
            (`contradicted_by_centre`: traced back into the centre view, the value lands in
            the frame on a surface that is not nearer, so the centre would have projected
            it here). Otherwise it takes the nearest of three candidates that the centre
            view does not contradict: the inpainted value, the view's 2-D fill
            (``fill_choice``), and the farther of the nearest projected values of the same
            pixel in the cross-hair views before and after it. This mainly fixes the strips
            along the frame where content from outside the centre view's frame enters a
            view: there the inpainting and the 2-D fill see only the surface beside the
            strip, often a nearer one.
        visibility_passes: with ``visibility_fill``, how many 2-D fills a hole gets whose
            three candidates the centre view all contradicts. Pass ``k > 1`` fills those
            holes anew (``fill_choice``) from every other pixel, including the holes the
            passes before resolved, and a hole takes the value where the centre view does not
            contradict it. A disocclusion flanked by nearer surfaces along its row (or
            column) reaches the background it shows only through the holes above or below
            it, which the first pass resolves (synthetic slanted variant: worst view MSE×100
            1.10 → 0.91; not in the thesis). 1 = a single fill. A view without such
            holes skips the further passes.
        solver: `SolverConfig` of the batched EPI solves (thin ``A × L`` grids, where a
            Jacobi preconditioner is much faster than the batched multigrid).

    Raises:
        TypeError, ValueError: on construction, for a value of the wrong type or out of
            range.

    References:
        Thesis Ch. 6, eqs 6.5–6.8.
    """

    data_weight: Array = hyperparameter(15.0, differentiable=True, lower=0.0)
    centre_weight: Array = hyperparameter(1000.0, differentiable=True, lower=0.0)
    photo_sigma: Array = hyperparameter(0.1, differentiable=True, lower=0.0, lower_open=True)
    hole_weight: Array = hyperparameter(10.0, differentiable=True, lower=0.0)
    min_confidence: Array = hyperparameter(0.1, differentiable=False, lower=0.0)
    line_scale: Array = hyperparameter(1.0, differentiable=True, lower=0.0)
    line_floor: Array = hyperparameter(0.1, differentiable=True, lower=0.0)
    occlusion_tol: Array = hyperparameter(0.1, differentiable=False, lower=0.0)
    c: Array = hyperparameter(0.1, differentiable=True, lower=0.0)
    eps: Array = hyperparameter(1e-3, differentiable=True, lower=0.0, lower_open=True)
    cross_hair_fill: bool = static(True)
    fill_choice: str = static("colour", choices=FILL_CHOICES)
    hole_value: str = static("fill", choices=HOLE_VALUES)
    visibility_fill: bool = static(True)
    visibility_passes: int = static(2, lower=1, upper=8)
    visibility_tol: Array = hyperparameter(0.8, differentiable=False, lower=0.0)
    colour_margin: Array = hyperparameter(0.3, differentiable=False, lower=0.0)
    frame_margin: Array = hyperparameter(0.1, differentiable=False, lower=0.0)
    solver: SolverConfig = SolverConfig(preconditioner="jacobi", max_iters=1000)

    def __check_init__(self):
        check_fields(self)


class FillConfig(eqx.Module):
    """Views off the cross-hair: merge of their two reprojections and hole filling
    (`ReconstructConfig.fill`).

    Attributes (array leaves; "threshold" ones only switch discrete decisions, the others
    are differentiable):
        c: smoothness numerator of the hole-filling solve of off-cross-hair views.
        data_weight: data weight of the reprojected pixels in that solve.
        hole_weight: weight, in that solve, of the 2-D fill (`colour_fill` with
            ``colour_margin``) on holes: large = holes take the value of the 2-D fill,
            small = the colour-guided smoothness spreads the neighbours into them.
        min_confidence: (threshold) a merged pixel of an off-cross-hair view whose photometric
            confidence is at most this counts as a hole (0 = only pixels nothing landed on).
        colour_margin: (threshold) `colour_fill`'s ``margin`` for the 2-D fill of the holes
            (guide units as ``colour_space``, L1 over the channels): of the nearest valid
            values left, right, above and below, the one whose pixel's colour is nearest to
            the hole's replaces the farthest (the background a disocclusion shows) only where
            its colour is closer by more than this; 1e9: always the farthest
            (`background_fill`). A mixed pixel on a foreground boundary whose merged value
            lost its photometric confidence is a hole too, and its colour finds the
            foreground.
        frame_margin: (threshold) `fill_beyond_frame`'s ``margin`` (pixels per view step)
            after the 2-D fill: a hole in a row or column run of holes that reaches the
            frame's border takes the run's farthest filled value where that value's surface
            point lies beyond the centre view's frame and is farther than the hole's own
            value by more than this; 1e9: off.

    Attributes (static):
        hole_fill: ``"solve"`` (screened-Poisson fill guided by the view) or ``"background"``
            (the 2-D fill alone, `colour_fill` with ``colour_margin``) for off-cross-hair
            views.
        merge: ``"photo"`` (photometric-confidence-weighted mean of the two reprojections of an
            off-cross-hair view) or ``"mean"`` (the thesis' plain mean).
        crack_parallax: forwarded to `forward_project`.
        solver: `SolverConfig` of the hole-filling solves of off-cross-hair views.

    Raises:
        TypeError, ValueError: on construction, for a value of the wrong type or out of
            range (e.g. an unknown hole fill or merge name).

    References:
        Thesis Ch. 6 (off-cross-hair views: the mean of two reprojections); the photometric
        merge and the hole-filling solve are not in the thesis.
    """

    c: Array = hyperparameter(2.0, differentiable=True, lower=0.0)
    data_weight: Array = hyperparameter(1000.0, differentiable=True, lower=0.0)
    hole_weight: Array = hyperparameter(1000.0, differentiable=True, lower=0.0)
    min_confidence: Array = hyperparameter(0.5, differentiable=False, lower=0.0)
    colour_margin: Array = hyperparameter(0.2, differentiable=False, lower=0.0)
    frame_margin: Array = hyperparameter(0.1, differentiable=False, lower=0.0)
    hole_fill: str = static("solve", choices=HOLE_FILLS)
    merge: str = static("photo", choices=MERGES)
    crack_parallax: float = static(0.5, lower=0.0)
    solver: SolverConfig = SolverConfig(preconditioner="jacobi", max_iters=1000)

    def __check_init__(self):
        check_fields(self)


class ReconstructConfig(eqx.Module):
    """Configuration of the smooth 4D reconstruction, one sub-config per step of thesis
    Ch. 6.

    Array fields of the sub-configs are pytree leaves (sweep / `vmap` / differentiate
    without recompiling); the others are static. Array fields marked "threshold" only switch
    discrete decisions: the chain is piecewise constant in them (zero gradient where it
    exists); the others are differentiable (`mvedge_jax.pipeline.hyperparameter_paths`).

    Attributes:
        colour_space: ``"lab"`` (CIELAB / 100) or ``"rgb"`` guide for the smoothness terms.
        centre: `CentreConfig`: centre-view diffusion (eqs 6.1–6.3).
        seeds: `SeedConfig`: photo-consistent samples of the centre diffusion where no
            edge label is near.
        sharpen: `SharpenConfig`: sharpening of the centre map (Sec. 6.1), boundary
            snapping and matting.
        select: `SelectConfig`: merge of an optimised centre map (`select_centre`, Ch. 7).
        epi: `EpiConfig`: cross-hair projection and angular inpainting (eqs 6.5–6.8).
        fill: `FillConfig`: views off the cross-hair.

    Raises:
        TypeError: on a value of the wrong type (e.g. a number for ``colour_space``, or a
            sub-config of the wrong class).
        ValueError: on an unknown colour space (the sub-configs check their own fields when
            they are built).

    References:
        Thesis Ch. 6, eqs 6.1–6.8.
    """

    colour_space: str = static("lab", choices=COLOUR_SPACES)
    centre: CentreConfig = CentreConfig()
    seeds: SeedConfig = SeedConfig()
    sharpen: SharpenConfig = SharpenConfig()
    select: SelectConfig = SelectConfig()
    epi: EpiConfig = EpiConfig()
    fill: FillConfig = FillConfig()

    def __check_init__(self):
        check_fields(self)
