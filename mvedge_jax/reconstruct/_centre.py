"""Centre-view depth diffusion from the multi-view edge model (thesis Sec. 6.1, eqs 6.1–6.3)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Float

from ..edges import EdgeSet
from ..lightfield import rgb_to_lab, srgb_to_linear
from ..solve import SolveResult, guide_differences, guide_edge_weights, solve_poisson
from ._config import ReconstructConfig
from ._photo import _block_upsample, _window_extrema

if TYPE_CHECKING:  # pragma: no cover
    from ..surface import SurfaceResult


def colour_guide(image: Float[ArrayLike, "... 3"], colour_space: str) -> Float[Array, "... 3"]:
    """A guide image: CIELAB / 100 (``"lab"``), the sRGB values as given (``"rgb"``) or
    linear light (``"linear"``, `srgb_to_linear`)."""
    image = jnp.asarray(image)
    if not jnp.issubdtype(image.dtype, jnp.floating):
        image = image.astype(jnp.float32)
    if colour_space == "lab":
        return rgb_to_lab(image) / 100.0
    if colour_space == "linear":
        return srgb_to_linear(image)
    return image


def splat_bilinear(
    x: Float[Array, " N"],
    y: Float[Array, " N"],
    value: Float[Array, " N"],
    weight: Float[Array, " N"],
    shape: tuple[int, int],
    corner_scale: Callable[[Array, Array], Array] | None = None,
) -> tuple[Float[Array, "H W"], Float[Array, "H W"]]:
    """Bilinear splat of weighted labels onto a pixel grid.

    Point ``i`` at sub-pixel ``(x_i, y_i)`` (pixel centres at integers) spreads its weight over
    the four surrounding pixels with bilinear coefficients ``b``. The quadratic data energy
    ``Σ_i Σ_k w_i b_ik (D_k − v_i)²`` equals, up to a constant, ``Σ_k λ_k (D_k − S_k)²`` with
    ``λ_k = Σ_i w_i b_ik`` and ``S_k = Σ_i w_i b_ik v_i / λ_k`` — the two returned maps.
    Points (or corners) outside the grid are dropped; zero weight marks padding.
    ``corner_scale(col, row)``, given the ``(N,)`` int32 column and row of one corner of every
    point (clipped into the grid), returns ``(N,)`` factors of that corner's coefficient
    (`splat_mask`).

    Returns:
        ``(data_weight (H, W), target (H, W))``; ``target`` is 0 where ``data_weight`` is 0.
    """
    H, W = shape
    x0 = jnp.floor(x)
    y0 = jnp.floor(y)
    fx = x - x0
    fy = y - y0
    x0 = x0.astype(jnp.int32)
    y0 = y0.astype(jnp.int32)
    lam = jnp.zeros((H, W), weight.dtype)
    num = jnp.zeros((H, W), weight.dtype)
    for oy, ox, b in (
        (0, 0, (1 - fx) * (1 - fy)),
        (0, 1, fx * (1 - fy)),
        (1, 0, (1 - fx) * fy),
        (1, 1, fx * fy),
    ):
        xi = x0 + ox
        yi = y0 + oy
        inside = (xi >= 0) & (xi < W) & (yi >= 0) & (yi < H)
        if corner_scale is not None:
            b = b * corner_scale(jnp.clip(xi, 0, W - 1), jnp.clip(yi, 0, H - 1))
        wb = jnp.where(inside, weight * b, 0.0)
        yi = jnp.where(inside, yi, H)  # out of bounds -> dropped
        lam = lam.at[yi, xi].add(wb, mode="drop")
        num = num.at[yi, xi].add(wb * value, mode="drop")
    pos = lam > 0
    target = jnp.where(pos, num / jnp.where(pos, lam, 1.0), 0.0)
    return lam, target


def edge_data_weight(step_response: Array, config: ReconstructConfig) -> Array:
    """``ω · exp(a · clip(λ_e, 0, λ_max))`` (eq 6.3)."""
    lam_e = jnp.clip(step_response, 0.0, config.centre.lambda_e_max)
    return config.centre.omega * jnp.exp(config.centre.a * lam_e)


def _pair_max(m: Array) -> tuple[Array, Array]:
    """Per-edge maximum of a per-pixel map: ``(H, W-1)`` and ``(H-1, W)``."""
    return jnp.maximum(m[:, 1:], m[:, :-1]), jnp.maximum(m[1:, :], m[:-1, :])


def smoothness_weights(
    guide: Float[Array, "H W C"],
    confidence: Float[Array, "H W"],
    c: Array,
    eps: Array,
    beta: Array,
) -> tuple[Float[Array, "H W-1"], Float[Array, "H-1 W"]]:
    """``c / ((|∇I| + ε)(1 + β · conf))`` on the 4-neighbour edges (eq 6.2 with Sec. 4.3)."""
    wx, wy = guide_edge_weights(guide, scale=c, eps=eps)
    cx, cy = _pair_max(jnp.clip(confidence, 0.0, 1.0))
    return wx / (1.0 + beta * cx), wy / (1.0 + beta * cy)


def _upsample2(img: Array) -> Array:
    """Bilinear 2× upsampling with pixel centres aligned (fine ``i`` ↔ coarse ``(i - 0.5) / 2``)."""
    H, W = img.shape[:2]
    return jax.image.resize(img, (2 * H, 2 * W) + img.shape[2:], method="linear")


def _downsample2(img: Array) -> Array:
    H2, W2 = img.shape
    return img.reshape(H2 // 2, 2, W2 // 2, 2).mean(axis=(1, 3))


def label_positions(
    edges: EdgeSet, surface: SurfaceResult, config: ReconstructConfig
) -> tuple[Array, Array, Array]:
    """``(qx, qy, use)``: where each edge label enters the centre diffusion,
    ``p + centre.offset_scale · n`` (``n`` its surface vector; pixels), and which labels do
    (valid and visible in the centre view)."""
    off = jnp.asarray(surface.offset)
    qx = edges.x + config.centre.offset_scale * off[:, 0]
    qy = edges.y + config.centre.offset_scale * off[:, 1]
    return qx, qy, edges.valid & edges.visible


#: Distance (pixels) from an edge point, along its surface vector ``n``, of the pixel whose
#: colour stands for the point's own surface (``p + 2n``) and of the pixel across the edge
#: (``p − 2n``) in `splat_mask`.
SIDE_DISTANCE = 2.0


def _side_pixel(edges: EdgeSet, offset: Array, distance: float, k: int, shape) -> tuple:
    """``(row, col)`` int32 ``(N,)``: the pixel of the ``k×`` grid nearest to
    ``p + distance · n``."""
    Hk, Wk = shape
    sx = k * (edges.x + distance * offset[:, 0]) + 0.5 * (k - 1)
    sy = k * (edges.y + distance * offset[:, 1]) + 0.5 * (k - 1)
    row = jnp.clip(jnp.round(sy).astype(jnp.int32), 0, Hk - 1)
    col = jnp.clip(jnp.round(sx).astype(jnp.int32), 0, Wk - 1)
    return row, col


def uniform_window(guide: Float[Array, "H W C"]) -> Float[Array, "H W"]:
    """Largest colour difference (Euclidean over the channels, guide units) between two
    4-neighbours of which one lies in the pixel's 3×3 window: small on a uniform region."""
    dx, dy = guide_differences(guide)  # as the smoothness weights: XLA computes them once
    zx = jnp.zeros_like(dx[:, :1])
    zy = jnp.zeros_like(dy[:1])
    gx = jnp.maximum(jnp.concatenate([zx, dx], axis=1), jnp.concatenate([dx, zx], axis=1))
    gy = jnp.maximum(jnp.concatenate([zy, dy], axis=0), jnp.concatenate([dy, zy], axis=0))
    return _window_extrema(jnp.maximum(gx, gy), 1)[1]


def splat_mask(
    guide: Float[Array, "H W C"],
    edges: EdgeSet,
    offset: Float[Array, "N 2"],
    config: ReconstructConfig,
    k: int = 1,
) -> Callable[[Array, Array], Array]:
    """The ``corner_scale`` of `splat_bilinear` for the centre diffusion: a label keeps its
    splat off a uniform region across its edge.

    Where the pixel ``p − 2n`` across point ``p``'s edge (``n`` its surface vector) lies on a
    uniform region (`uniform_window` below ``centre.splat_uniform``), a splat corner whose
    colour differs from the point's own surface (the guide at ``p + 2n``) by more than
    ``centre.splat_colour`` (Euclidean, guide units) gets no weight: a uniform region has
    no label of its own, so a label that lands on it sets its whole disparity. Elsewhere
    the coefficients stay bilinear. ``centre.splat_uniform = 0`` turns the test off.

    With ``centre.splat_side_ratio = ρ > 0``, a corner also gets no weight wherever its
    colour differs from the point's own surface by more than ``centre.splat_colour`` and
    lies nearer the colour across the edge (the guide at ``p − 2n``) than ``ρ`` times its
    distance to the own surface's: the corner shows the other side, as where a point is
    placed a pixel or two off its colour edge and its splat lands beyond it (a strip of
    uniform floor between a wall and a nearer panel, too narrow for the uniform-region
    test). ``ρ = 0`` (the default) turns this test off.
    Not in the thesis (docs/ACCURACY.md, "Splat off uniform regions", "Splat corners that
    show the other side").

    Args:
        guide: ``(H, W, C)`` colour guide on the solve grid (``k×`` the centre view).
        edges: `EdgeSet` (centre-view positions).
        offset: ``(N, 2)`` surface vectors.
        config: `ReconstructConfig` (``centre.splat_uniform``, ``centre.splat_colour``,
            ``centre.splat_side_ratio``).
        k: the solve grid's factor (``centre.upsample``).

    Returns:
        ``corner_scale(col, row) -> (N,)`` factors in ``{0, 1}`` (piecewise constant: no
        gradient).
    """
    shape = guide.shape[:2]
    offset = jnp.asarray(offset)
    guide = lax.stop_gradient(guide)
    # Colour planes: gathers from (H, W) planes vectorise, from channels-last pixels not.
    planes = [guide[..., c] for c in range(guide.shape[-1])]
    own_px = _side_pixel(edges, offset, SIDE_DISTANCE, k, shape)
    own = [p[own_px] for p in planes]
    across = _side_pixel(edges, offset, -SIDE_DISTANCE, k, shape)
    uniform = uniform_window(guide)[across] < config.centre.splat_uniform
    limit = jnp.square(config.centre.splat_colour)
    other = [p[across] for p in planes]
    ratio2 = jnp.square(config.centre.splat_side_ratio)

    def corner_scale(col: Array, row: Array) -> Array:
        d_own = sum(jnp.square(p[row, col] - o) for p, o in zip(planes, own, strict=True))
        d_other = sum(jnp.square(p[row, col] - o) for p, o in zip(planes, other, strict=True))
        far = d_own > limit
        other_side = d_other < ratio2 * d_own
        return jnp.where(far & (uniform | other_side), 0.0, 1.0).astype(guide.dtype)

    return corner_scale


def centre_problem(
    edges: EdgeSet,
    surface: SurfaceResult,
    centre_view: Float[Array, "H W 3"],
    config: ReconstructConfig,
    seeds: tuple[Array, Array] | None = None,
):
    """The arrays of the centre-view problem (eq 6.1) on the solve grid (``seeds``: as
    `centre_disparity`).

    Returns:
        ``(data_weight, target, weight_x, weight_y)`` on the ``upsample×`` grid.
    """
    H, W = centre_view.shape[:2]
    k = config.centre.upsample
    qx, qy, use = label_positions(edges, surface, config)
    w = jnp.where(use, edge_data_weight(jnp.asarray(surface.step_response), config), 0.0)
    guide = colour_guide(centre_view, config.colour_space)
    conf = jnp.asarray(surface.depth_edge_confidence)
    if k == 2:
        guide = _upsample2(guide)
        conf = _upsample2(conf)
        qx = 2.0 * qx + 0.5
        qy = 2.0 * qy + 0.5
    mask = splat_mask(guide, edges, surface.offset, config, k)
    lam, target = splat_bilinear(qx, qy, edges.disparity, w, (k * H, k * W), mask)
    if seeds is not None:
        seed_weight, seed_value = (jnp.asarray(a, lam.dtype) for a in seeds)
        seed_weight = _block_upsample(seed_weight, k, (k * H, k * W))
        seed_value = _block_upsample(seed_value, k, (k * H, k * W))
        total = lam + seed_weight
        pos = total > 0
        target = jnp.where(
            pos, (lam * target + seed_weight * seed_value) / jnp.where(pos, total, 1.0), 0.0
        )
        lam = total
    wx, wy = smoothness_weights(
        guide, conf, config.centre.c, config.centre.eps, config.centre.conf_beta
    )
    return lam, target, wx, wy


def _check_inputs(edges: EdgeSet, surface, centre_view, seeds=None) -> tuple[int, int]:
    centre_view = jnp.asarray(centre_view)
    if centre_view.ndim != 3 or centre_view.shape[-1] != 3:
        raise ValueError(f"centre_view must have shape (H, W, 3); got {tuple(centre_view.shape)}")
    H, W = centre_view.shape[:2]
    N = edges.capacity
    if tuple(surface.offset.shape) != (N, 2):
        raise ValueError(
            f"surface.offset must have shape ({N}, 2); got {tuple(surface.offset.shape)}"
        )
    if tuple(surface.step_response.shape) != (N,):
        raise ValueError(
            f"surface.step_response must have shape ({N},); "
            f"got {tuple(surface.step_response.shape)}"
        )
    if tuple(surface.depth_edge_confidence.shape) != (H, W):
        raise ValueError(
            f"surface.depth_edge_confidence must have shape {(H, W)}; "
            f"got {tuple(surface.depth_edge_confidence.shape)}"
        )
    if seeds is not None:
        if len(seeds) != 2 or any(tuple(jnp.shape(a)) != (H, W) for a in seeds):
            raise ValueError(
                f"seeds must be (weight, value), each of shape {(H, W)}; "
                f"got shapes {[tuple(jnp.shape(a)) for a in seeds]}"
            )
    return H, W


def centre_disparity(
    edges: EdgeSet,
    surface: SurfaceResult,
    centre_view: Float[ArrayLike, "H W 3"],
    config: ReconstructConfig = ReconstructConfig(),
    seeds: tuple[Float[ArrayLike, "H W"], Float[ArrayLike, "H W"]] | None = None,
) -> Float[Array, "H W"]:
    """Dense centre-view disparity by edge-aware diffusion of the edge labels (eq 6.1).

    Every valid edge point visible in the centre view is splatted (bilinearly, sub-pixel) at
    ``p + centre.offset_scale · n`` — ``n`` its surface vector, pointing to the surface its
    label belongs to — with data weight ``ω · exp(a · λ_e)`` (eq 6.3; ``λ_e`` the step response of
    the bidirectional diffusion); next to a uniform region across its edge, its splat
    corners of another colour than its own surface get no weight (`splat_mask`; not in the
    thesis). Smoothness between 4-neighbours is
    ``c / ((|∇I| + ε)(1 + β · conf))``: weak across colour edges and across likely depth edges
    (``conf`` the depth-edge confidence map of Sec. 4.3). The screened-Poisson problem is solved
    with `solve_poisson` (PCG to ``config.centre.solver.rtol``), optionally on a 2× grid and
    averaged back. Pixels in a region with no label at all come out 0 (minimum-norm solution).
    With ``seeds = (weight, value)`` (e.g. from `centre_seeds`: photo-consistent samples
    where no edge label is near) each pixel's data term gains ``weight · (D − value)²``.

    Differentiable w.r.t. the array leaves of ``config`` (``centre.omega``, ``centre.a``,
    ``centre.c``, …), the edge disparities and the surface's step responses / confidence map
    (custom-VJP solve). jit-able (``config`` is a pytree; its static fields select the code path).

    Args:
        edges: `EdgeSet` of capacity ``N`` (centre-view positions, disparities, ``visible``).
        surface: `SurfaceResult` with ``offset (N, 2)``, ``step_response (N,)`` and
            ``depth_edge_confidence (H, W)``.
        centre_view: ``(H, W, 3)`` float RGB in [0, 1].
        config: `ReconstructConfig`.
        seeds: optional ``(weight (H, W), value (H, W))`` extra samples (weight 0: none;
            value in pixels per view step).

    Returns:
        ``(H, W)`` disparity (pixels per view step), float32 (float64 with float64 inputs).

    Raises:
        ValueError: on inconsistent shapes (quoted).

    References:
        Thesis Sec. 6.1, eqs 6.1–6.3; Sec. 4.2–4.3 (surface vectors, depth-edge confidence).
    """
    return solve_centre(edges, surface, centre_view, config, seeds)[0]


def solve_centre(
    edges: EdgeSet,
    surface: SurfaceResult,
    centre_view: Float[ArrayLike, "H W 3"],
    config: ReconstructConfig = ReconstructConfig(),
    seeds: tuple[Float[ArrayLike, "H W"], Float[ArrayLike, "H W"]] | None = None,
) -> tuple[Float[Array, "H W"], SolveResult]:
    """`centre_disparity` and the `SolveResult` of its screened-Poisson solve (on the
    ``centre.upsample``× grid: its ``x`` is not averaged back), for convergence checks.

    Args, Raises, References: as `centre_disparity`.
    """
    _check_inputs(edges, surface, centre_view, seeds)
    centre_view = jnp.asarray(centre_view)
    if not jnp.issubdtype(centre_view.dtype, jnp.floating):
        centre_view = centre_view.astype(jnp.float32)
    lam, target, wx, wy = centre_problem(edges, surface, centre_view, config, seeds)
    sol = solve_poisson(lam, target, wx, wy, config=config.centre.solver)
    x = sol.x
    if config.centre.upsample == 2:
        x = _downsample2(x)
    return x, sol
