"""`SuperpixelConfig`: every option of the view-consistent 4D superpixels (thesis Ch. 5)."""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array

from ..edges import EdgeConfig
from ..surface import SurfaceConfig

_f32 = lambda v: jnp.asarray(v, jnp.float32)  # noqa: E731

#: Offsets ``(sx, sy)`` of the k-means seed grid, in grid cells, in the order
#: ``SuperpixelConfig.seed_candidates`` takes them (the first is SLIC's grid).
SEED_SHIFTS: tuple[tuple[float, float], ...] = (
    (0.0, 0.0),
    (0.5, 0.0),
    (0.0, 0.5),
    (0.5, 0.5),
    (0.25, 0.25),
    (-0.25, 0.25),
    (0.25, -0.25),
    (-0.25, -0.25),
)


class SuperpixelConfig(eqx.Module):
    """Configuration of `superpixels` and `kmeans_superpixels`.

    Static values change shapes, the number of clusters or host-side decisions (changing them
    recompiles); the label-propagation weights are float32 array leaves.

    Attributes (static):
        size: mean superpixel side in pixels; the number of superpixels is
            ``round(H * W / size²)`` (thesis: sizes 15–40).
        line_capacity: EPI lines kept per EPI (the most confident; the rest are counted as
            dropped).
        segment_capacity: EPI segments kept per EPI; ``None``: ``line_capacity + 2 +
            2 * ceil(width / split_width)``.
        merge_distance: neighbouring lines of one EPI closer than this (pixels, centre row) and
            with disparities within ``merge_disparity`` are one line (the detector reports an
            edge on each of the adjacent pixels it straddles).
        merge_disparity: see ``merge_distance`` (pixels per view step).
        omega_d: ω_d of eq 4.7, the weight of the disparity difference against the spatial
            distance of two lines in the matching weight.
        occlusion_tol: two lines cross (an occlusion) only if their disparities differ by more
            than this (pixels per view step).
        side_min: a surface vector decides the side of a line in an EPI only if its component
            along the EPI's spatial axis is at least this (unit vector); otherwise the side is
            unknown and both sides of the line stay open.
        split_width: segments wider than this (pixels, centre view) are split into equal parts
            by new lines with the segment's disparity, interpolated on a slanted segment (see
            ``slant_tol``) (thesis: 15).
        slant_tol: a bounding line whose disparity is within this of its segment's
            (pixels per view step) lies on the segment's surface: the segment's disparity
            then varies linearly between its two lines (cuts included) and every pixel is
            projected with its own disparity; 0 gives the thesis' piece-wise constant
            disparity per segment (not in the thesis; see docs/SUPERPIXELS.md).
        weight_xy: k-means weight of the x and y features (thesis 1).
        weight_d: k-means weight of the disparity normalised to [0, 1] over the scene's range
            (thesis 120).
        weight_lab: k-means weight of L*, a*, b* (thesis 3), applied to ``lab_scale * LAB``.
        lab_scale: unit of the colour features: CIELAB is multiplied by this before
            ``weight_lab`` (1: L* in [0, 100]).
        kmeans_iters: Lloyd iterations of the clustering (scikit-learn ``max_iter``).
        seed_candidates: with ``centre_first``, `superpixels` clusters from this many seed
            grids (the first ``seed_candidates`` offsets of ``SEED_SHIFTS``), labels the
            centre view of each, and keeps the partition with the lowest predicted
            self-similarity error: the centre labels moved into every view with the centre
            disparity (the dense ``disparity`` if given, else the EPI segments'), z-buffered,
            each visible pixel counted at its centre position (no ground truth involved;
            not in the thesis). 1: SLIC's grid only (the thesis). At most
            ``len(SEED_SHIFTS)`` (8). Default 6 (docs/SUPERPIXELS.md).
        keep_disagreeing: with ``centre_first=False``, where the horizontal and vertical
            segmentations disagree, keep the nearer one's label (ties: the horizontal)
            instead of unlabelling the pixel (thesis: unlabel, then propagate).
        centre_first: label the centre view completely first (its agreeing pixels, eq 5.1,
            nearest fill), then keep a projected label in any view only where it is the
            centre's label at the pixel moved back to the centre by its own disparity
            (disagreements settled by whichever segmentation matches; both: the nearer),
            and fill the holes with the centre labels forward-projected; only what the
            centre view does not see goes to the cross-hair propagation. False: the thesis'
            order (drop disagreements, propagate on the cross-hair). Not in the thesis; see
            docs/SUPERPIXELS.md.
        smooth_radius: with ``centre_first``, the centre labels pass a majority (mode) filter
            of this chessboard radius (pixels; a pixel keeps its label on ties) before the
            connectivity step; 0: none (not in the thesis). Default 2: with a dense
            ``disparity`` it lowered labels per pixel and raised compactness on all four
            measured scenes (docs/RESULTS.md, "Superpixels"); without one it trades labels per
            pixel (slightly higher at sizes 15–20) for compactness and self-similarity.
        connected: with ``centre_first``, every label keeps only its largest 4-connected
            piece of the centre view; the other pieces are refilled by nearest fill before
            the projection (removes scattered fragments of a cluster; not in the thesis).
        dense_tol: with a dense per-view ``disparity`` passed to `superpixels`, a pixel the
            forward projection of the centre labels misses takes the centre label at the pixel
            its own disparity points to when the centre disparity there is within this many
            pixels per view step of its own (not in the thesis).
        refine_iters: with ``centre_first`` and a dense ``disparity`` passed to `superpixels`,
            iterations of a local (SLIC-style) k-means of the centre view's pixels that starts
            from the segment clusters, before the majority filter: each pixel moves to the
            nearest label centre among the labels at offsets ``{-1, 0, 1}²`` and
            ``{-r, 0, r}²`` around it, in the clustering's weighted ``(x, y, d, L*, a*, b*)``
            with ``d`` the dense centre disparity (not in the thesis). 0 (default): none. It
            moves boundaries onto depth edges (depth-edge recall, ASA and undersegmentation
            error improve) but raised the self-similarity error and labels per pixel on the
            measured scenes (docs/SUPERPIXELS.md), so it is off by default.
        refine_radius: ``r`` above (pixels, chessboard); 0: ``max(1, round(size / 2))``.
        propagation_radius: label propagation (eq 5.1) looks for labelled pixels within this
            chessboard radius (pixels).
        propagation_passes: passes of the propagation; each fills unlabelled pixels within
            ``propagation_radius`` of a labelled one.
        edges: configuration of `detect_edges` when `superpixels` detects the edges itself.
        surface: configuration of `surface_vectors` when `superpixels` computes them.

    Attributes (array leaves):
        w_colour: ω_c of eq 5.1 (thesis 1), on squared CIELAB differences (L* in [0, 100]).
        w_spatial: ω_s of eq 5.1 (thesis 1), on squared pixel distances.
        w_photo: ω_d of eq 5.1 (thesis 1e-5), on the summed absolute CIELAB difference to the
            four end views of the cross-hair at the candidate's disparity.

    Raises:
        ValueError: on construction, for out-of-range values.

    References:
        Thesis Sec. 4.2.1 (Alg. 2, eq 4.7), Sec. 5.1.1 (clustering weights, eq 5.1).
    """

    size: float = eqx.field(static=True, default=20.0)
    line_capacity: int = eqx.field(static=True, default=192)
    segment_capacity: int | None = eqx.field(static=True, default=None)
    merge_distance: float = eqx.field(static=True, default=1.5)
    merge_disparity: float = eqx.field(static=True, default=0.25)
    omega_d: float = eqx.field(static=True, default=0.9)
    occlusion_tol: float = eqx.field(static=True, default=0.1)
    side_min: float = eqx.field(static=True, default=0.3)
    split_width: float = eqx.field(static=True, default=15.0)
    slant_tol: float = eqx.field(static=True, default=0.3)
    weight_xy: float = eqx.field(static=True, default=1.0)
    weight_d: float = eqx.field(static=True, default=120.0)
    weight_lab: float = eqx.field(static=True, default=3.0)
    lab_scale: float = eqx.field(static=True, default=0.2)
    kmeans_iters: int = eqx.field(static=True, default=20)
    seed_candidates: int = eqx.field(static=True, default=6)
    keep_disagreeing: bool = eqx.field(static=True, default=False)
    centre_first: bool = eqx.field(static=True, default=True)
    connected: bool = eqx.field(static=True, default=True)
    smooth_radius: int = eqx.field(static=True, default=2)
    dense_tol: float = eqx.field(static=True, default=0.5)
    refine_iters: int = eqx.field(static=True, default=0)
    refine_radius: int = eqx.field(static=True, default=0)
    propagation_radius: int = eqx.field(static=True, default=2)
    propagation_passes: int = eqx.field(static=True, default=2)
    w_colour: Array = eqx.field(converter=_f32, default=1.0)
    w_spatial: Array = eqx.field(converter=_f32, default=1.0)
    w_photo: Array = eqx.field(converter=_f32, default=1e-5)
    edges: EdgeConfig = EdgeConfig()
    surface: SurfaceConfig = SurfaceConfig()

    def __check_init__(self):
        if not (math.isfinite(self.size) and self.size >= 2):
            raise ValueError(f"SuperpixelConfig.size must be >= 2 pixels; got {self.size}")
        for name in ("line_capacity", "kmeans_iters", "propagation_radius"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"SuperpixelConfig.{name} must be >= 1; got {getattr(self, name)}")
        if not 1 <= int(self.seed_candidates) <= len(SEED_SHIFTS):
            raise ValueError(
                f"SuperpixelConfig.seed_candidates must be in [1, {len(SEED_SHIFTS)}]; "
                f"got {self.seed_candidates}"
            )
        if self.smooth_radius < 0:
            raise ValueError(
                f"SuperpixelConfig.smooth_radius must be >= 0; got {self.smooth_radius}"
            )
        for name in ("refine_iters", "refine_radius"):
            if int(getattr(self, name)) < 0:
                raise ValueError(f"SuperpixelConfig.{name} must be >= 0; got {getattr(self, name)}")
        if self.propagation_passes < 0:
            raise ValueError(
                f"SuperpixelConfig.propagation_passes must be >= 0; got {self.propagation_passes}"
            )
        if self.segment_capacity is not None and self.segment_capacity < 2:
            raise ValueError(
                f"SuperpixelConfig.segment_capacity must be >= 2; got {self.segment_capacity}"
            )
        if not 0.0 <= self.omega_d <= 1.0:
            raise ValueError(f"SuperpixelConfig.omega_d must be in [0, 1]; got {self.omega_d}")
        if self.keep_disagreeing and self.centre_first:
            raise ValueError(
                "SuperpixelConfig.keep_disagreeing needs centre_first=False (the centre view "
                "settles disagreements otherwise)"
            )
        if not self.split_width >= 2:
            raise ValueError(f"SuperpixelConfig.split_width must be >= 2; got {self.split_width}")
        for name in (
            "merge_distance",
            "merge_disparity",
            "occlusion_tol",
            "side_min",
            "slant_tol",
            "weight_xy",
            "weight_d",
            "weight_lab",
            "lab_scale",
            "dense_tol",
        ):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"SuperpixelConfig.{name} must be finite and >= 0; got {v}")
        for name in ("w_colour", "w_spatial", "w_photo"):
            try:
                v = float(getattr(self, name))
            except Exception:  # traced
                continue
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"SuperpixelConfig.{name} must be finite and >= 0; got {v}")

    def n_superpixels(self, height: int, width: int) -> int:
        """Number of clusters for ``height × width`` views: ``max(1, round(H W / size²))``."""
        return max(1, round(height * width / (self.size * self.size)))

    def segments_per_epi(self, width: int) -> int:
        """The segment capacity per EPI for an EPI ``width`` pixels wide."""
        if self.segment_capacity is not None:
            return int(self.segment_capacity)
        return int(self.line_capacity + 2 + 2 * math.ceil(width / self.split_width))
