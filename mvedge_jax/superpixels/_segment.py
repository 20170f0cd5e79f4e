"""Occlusion-aware EPI segmentation: pairing EPI lines into depth-ordered segments (Sec. 4.2.1).

Every EPI line is stored as its position ``p`` on the centre row (the centre view) and its
disparity ``d``; on the EPI row of view offset ``t`` (view index minus the centre index) it
lies at ``p - t d`` (SPEC §0). A segment is the band between a left and a right line with a
disparity; in every row an EPI pixel belongs to the nearest (largest-disparity) segment that
covers it, so segments that pass behind a nearer one are occluded there.

Line pairing (Alg. 2) runs on the host with `scipy.optimize.linear_sum_assignment` (exact
maximum-weight bipartite matching); rendering the segments into EPI label maps is jitted and
mapped over EPIs.
"""

from __future__ import annotations

import functools
import math
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int
from scipy.optimize import linear_sum_assignment

from ..edges import HORIZONTAL, VERTICAL, EdgeSet
from ._config import SuperpixelConfig

_BIG = 1e9
_EPS = 0.5  # pixels added to eq 4.7's distance so that coincident lines get a finite weight


class EPISegments(eqx.Module):
    """Segments of ``E`` EPIs of one direction, fixed capacity ``S`` per EPI.

    Positions are along the EPI's spatial axis (x for horizontal EPIs, y for vertical ones) on
    the centre row, in pixels (pixel centres at integers); disparities in pixels per view step.
    The image borders are lines at ``-0.5`` and ``width - 0.5`` with disparity 0 (they do not
    move across views).

    Attributes:
        left_pos, left_disp: ``(E, S)`` float32, the segment's left line.
        right_pos, right_disp: ``(E, S)`` float32, its right line.
        disparity: ``(E, S)`` float32, the segment's disparity (its depth order).
        known: ``(E, S)`` bool, the disparity came from a bounding line whose surface faces
            the segment (else it is a provisional value, replaced by `resolve_unknown`; see
            `match_lines`).
        left_cut, right_cut: ``(E, S)`` bool, the bounding line was added by splitting (its
            disparity is the segment's).
        valid: ``(E, S)`` bool.
        n_dropped: ``()`` int32, lines and segments lost to the capacities.
        surface_left, surface_right: ``(E, S)`` float32 or ``None``, the disparity of the
            segment's surface at its left and right line; a pixel's disparity is interpolated
            linearly between them across the segment (a slanted surface). ``None``: both are
            ``disparity`` (piece-wise constant).
    """

    left_pos: Float[Array, "E S"]
    left_disp: Float[Array, "E S"]
    right_pos: Float[Array, "E S"]
    right_disp: Float[Array, "E S"]
    disparity: Float[Array, "E S"]
    known: Array
    left_cut: Array
    right_cut: Array
    valid: Array
    n_dropped: Int[Array, ""]
    surface_left: Float[Array, "E S"] | None = None
    surface_right: Float[Array, "E S"] | None = None

    def with_disparity(self, disparity: Float[Array, "E S"], known: Array) -> EPISegments:
        """The same segments with new disparities: a segment whose disparity changes becomes
        fronto-parallel at it (its surface ends and cut lines take it)."""
        changed = disparity != self.disparity
        sl = self.disparity if self.surface_left is None else self.surface_left
        sr = self.disparity if self.surface_right is None else self.surface_right
        return EPISegments(
            left_pos=self.left_pos,
            left_disp=jnp.where(self.left_cut & changed, disparity, self.left_disp),
            right_pos=self.right_pos,
            right_disp=jnp.where(self.right_cut & changed, disparity, self.right_disp),
            disparity=disparity,
            known=known,
            left_cut=self.left_cut,
            right_cut=self.right_cut,
            valid=self.valid,
            n_dropped=self.n_dropped,
            surface_left=jnp.where(changed, disparity, sl),
            surface_right=jnp.where(changed, disparity, sr),
        )


def _lsa_pairs(weight: np.ndarray, allowed: np.ndarray) -> list[tuple[int, int]]:
    """Maximum-weight bipartite matching restricted to ``allowed`` edges (not necessarily
    perfect: every row may stay unmatched through a zero-weight dummy column)."""
    rows = np.flatnonzero(allowed.any(1))
    cols = np.flatnonzero(allowed.any(0))
    if rows.size == 0:
        return []
    sub_ok = allowed[np.ix_(rows, cols)]
    w = np.where(sub_ok, weight[np.ix_(rows, cols)], -_BIG)
    dummy = np.full((rows.size, rows.size), -_BIG)
    np.fill_diagonal(dummy, 0.0)
    r, c = linear_sum_assignment(np.concatenate([w, dummy], axis=1), maximize=True)
    return [
        (int(rows[a]), int(cols[b]))
        for a, b in zip(r, c, strict=True)
        if b < cols.size and sub_ok[a, b]
    ]


def match_lines(
    pos: np.ndarray,
    disp: np.ndarray,
    side: np.ndarray,
    n_views: int,
    width: int,
    config: SuperpixelConfig,
    fallback_disparity: float = 0.0,
) -> np.ndarray:
    """Pair the lines of one EPI into segments (Alg. 2) and split wide segments.

    Lines are extended by the two image borders. A line is *occluding* when it crosses another
    line within the EPI's rows and has the larger disparity (by more than
    ``config.occlusion_tol``). The side of a line's own surface comes from its surface vector
    (``side``: +1 towards larger positions, -1 towards smaller ones, 0 unknown); an occluding
    line only bounds a segment on that side. Pairing a line ``i`` (left boundary) with a line
    ``j`` to its right (centre row) has weight ``1 / (Distance(i, j) + 0.5 px)`` with eq 4.7's
    distance ``ω_d |(t_i - b_i) - (t_j - b_j)| + (1 - ω_d) |(t_i + b_i) - (t_j + b_j)|`` (``t``,
    ``b``: intercepts on the top and bottom rows). Step 1 matches the pairs involving an
    occluding line (not across another occluding line); step 2 matches the remaining free
    sides. Both are exact maximum-weight bipartite matchings
    (`scipy.optimize.linear_sum_assignment` with zero-weight dummies, so lines may stay
    unmatched).

    A segment's disparity is the smallest (deepest) disparity of its bounding lines whose
    surface vector points into it (thesis: "the larger (deeper) slope of the two segment
    lines"). When neither line's surface faces the segment, its surface lies behind both and
    its depth is unknown here: it is marked ``known = 0`` with the smaller line disparity (or
    ``fallback_disparity`` between two borders) as a provisional value, resolved from the
    other EPI direction (`resolve_unknown`). Segments wider than ``config.split_width`` on the
    centre row are split into equal parts by lines ("cuts") of the segment's disparity.

    Slanted surfaces (``config.slant_tol > 0``, not in the thesis): a bounding line of a known
    segment whose disparity is within ``slant_tol`` of the segment's lies on its surface; the
    surface's disparity at each line (``surface_left``, ``surface_right``) is then the
    line's own, else the segment's. Cuts take the disparity interpolated linearly between the
    two, and each part's disparity (depth order) is the smaller of its two ends.

    Args:
        pos: ``(n,)`` centre-row positions, ascending (pixels).
        disp: ``(n,)`` disparities (pixels per view step).
        side: ``(n,)`` int surface side (+1, -1 or 0).
        n_views: number of views along the EPI (its height).
        width: EPI width in pixels.
        config: parameters.
        fallback_disparity: disparity of a segment bounded only by image borders.

    Returns:
        ``(m, 10)`` float64 rows ``(left_pos, left_disp, right_pos, right_disp, disparity,
        known, left_is_cut, right_is_cut, surface_left, surface_right)``.

    References:
        Thesis Sec. 4.2.1, Alg. 2, eq 4.7, Fig. 4.4.
    """
    n = pos.size
    P = np.concatenate([[-0.5], pos, [width - 0.5]]).astype(np.float64)
    D = np.concatenate([[0.0], disp, [0.0]]).astype(np.float64)
    side = np.concatenate([[0], side, [0]]).astype(np.int64)
    border = np.zeros(n + 2, bool)
    border[[0, -1]] = True
    vc = n_views // 2
    t_lo, t_hi = -vc, n_views - 1 - vc
    dd = D[:, None] - D[None, :]
    dp = P[:, None] - P[None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = dp / dd  # row offset where line i meets line k: p_i - t d_i = p_k - t d_k
    cross = (np.abs(dd) > config.occlusion_tol) & (tx >= t_lo) & (tx <= t_hi)
    cross &= ~border[:, None] & ~border[None, :]
    occluding = (cross & (dd > 0)).any(axis=1)
    right_open = ~(occluding & (side < 0))  # i may be a left boundary (segment on its right)
    left_open = ~(occluding & (side > 0))
    right_open[-1] = False
    left_open[0] = False
    top = P - t_lo * D
    bot = P - t_hi * D
    dsum, ddif = top + bot, top - bot
    dist = config.omega_d * np.abs(ddif[:, None] - ddif[None, :]) * ~(
        border[:, None] | border[None, :]
    ) + (1.0 - config.omega_d) * np.abs(dsum[:, None] - dsum[None, :])
    weight = 1.0 / (dist + _EPS)
    right_of = P[None, :] > P[:, None]
    # Step 1: pairs with an occluding line, never across another occluding line.
    c = np.cumsum(occluding)
    idx = np.arange(n + 2)
    between = c[np.maximum(idx[None, :] - 1, 0)] - c[idx[:, None]]  # occluders in (i, j)
    allowed1 = right_open[:, None] & left_open[None, :] & right_of
    allowed1 &= (occluding[:, None] | occluding[None, :]) & (between <= 0)
    pairs = _lsa_pairs(weight, allowed1)
    for i, j in pairs:
        right_open[i] = False
        left_open[j] = False
    # Step 2: all remaining free sides.
    allowed2 = right_open[:, None] & left_open[None, :] & right_of
    pairs += _lsa_pairs(weight, allowed2)
    rows = []
    for i, j in pairs:
        facing = [D[k] for k, s in ((i, 1), (j, -1)) if not border[k] and side[k] == s]
        if facing:
            d, known = min(facing), 1.0
        else:  # the surface lies behind both lines: its depth is resolved later
            lines = [D[k] for k in (i, j) if not border[k]]
            d, known = (min(lines) if lines else fallback_disparity), 0.0
        # The surface's disparity at each bounding line: the line's own where it lies within
        # slant_tol of the segment's (the line is on the surface), else the segment's.
        ends = [d, d]
        if known and config.slant_tol > 0:
            ends = [
                D[k] if not border[k] and abs(D[k] - d) <= config.slant_tol else d for k in (i, j)
            ]
        w = P[j] - P[i]
        parts = max(1, math.ceil(w / config.split_width))
        step = (ends[1] - ends[0]) / parts
        cuts = [(P[i], D[i], 0.0, ends[0])]
        cuts += [
            (P[i] + w * q / parts, ends[0] + q * step, 1.0, ends[0] + q * step)
            for q in range(1, parts)
        ]
        cuts += [(P[j], D[j], 0.0, ends[1])]
        rows += [
            (a[0], a[1], b[0], b[1], min(a[3], b[3]), known, a[2], b[2], a[3], b[3])
            for a, b in zip(cuts[:-1], cuts[1:], strict=True)
        ]
    return np.asarray(rows, np.float64).reshape(-1, 10)


def _epi_lines(
    edges: EdgeSet, surface_offset: np.ndarray, direction: int, n_epis: int, config
) -> tuple[list[tuple[np.ndarray, np.ndarray, np.ndarray]], int]:
    """Per EPI: ascending centre-row positions, disparities and surface sides of its lines
    (near-duplicates merged, at most ``config.line_capacity`` kept by confidence)."""
    valid = np.asarray(edges.valid) & (np.asarray(edges.direction) == direction)
    x, y = np.asarray(edges.x)[valid], np.asarray(edges.y)[valid]
    d = np.asarray(edges.disparity)[valid]
    conf = np.asarray(edges.confidence)[valid]
    off = np.asarray(surface_offset)[valid]
    if direction == HORIZONTAL:
        epi, pos, comp = np.rint(y), x, off[:, 0]
    else:
        epi, pos, comp = np.rint(x), y, off[:, 1]
    epi = epi.astype(np.int64)
    side = np.where(np.abs(comp) >= config.side_min, np.sign(comp), 0).astype(np.int64)
    keep = (epi >= 0) & (epi < n_epis) & np.isfinite(pos) & np.isfinite(d)
    epi, pos, d, conf, side = epi[keep], pos[keep], d[keep], conf[keep], side[keep]
    order = np.lexsort((pos, epi))
    epi, pos, d, conf, side = epi[order], pos[order], d[order], conf[order], side[order]
    bounds = np.searchsorted(epi, np.arange(n_epis + 1))
    out, dropped = [], 0
    for e in range(n_epis):
        a, b = bounds[e], bounds[e + 1]
        p_, d_, c_, s_ = pos[a:b], d[a:b], conf[a:b], side[a:b]
        kept: list[int] = []
        for k in range(p_.size):
            if (
                kept
                and p_[k] - p_[kept[-1]] < config.merge_distance
                and abs(d_[k] - d_[kept[-1]]) < config.merge_disparity
            ):
                if c_[k] > c_[kept[-1]]:
                    kept[-1] = k
                continue
            kept.append(k)
        sel = np.asarray(kept, np.int64)
        if sel.size > config.line_capacity:
            dropped += sel.size - config.line_capacity
            sel = np.sort(sel[np.argsort(-c_[sel], kind="stable")[: config.line_capacity]])
        out.append((p_[sel], d_[sel], s_[sel]))
    return out, dropped


def segment_epis(
    edges: EdgeSet,
    surface_offset: Float[Array, "N 2"],
    direction: int,
    n_views: int,
    n_epis: int,
    width: int,
    config: SuperpixelConfig = SuperpixelConfig(),
) -> EPISegments:
    """Occlusion-aware segmentation of every EPI of one direction (thesis Sec. 4.2.1).

    The edge points of ``direction`` are grouped by EPI (horizontal: pixel row ``round(y)``,
    position ``x``; vertical: pixel column ``round(x)``, position ``y``), near-duplicates are
    merged, and each EPI's lines are paired by `match_lines` (host, SciPy). Fixed capacity
    ``config.segments_per_epi(width)`` per EPI; overflow is counted in ``n_dropped`` and warned.

    Args:
        edges: the multi-view edge set (`detect_edges`).
        surface_offset: ``(N, 2)`` surface vectors of the points (`SurfaceResult.offset`).
        direction: `HORIZONTAL` (0) or `VERTICAL` (1).
        n_views: views along the EPI (V for horizontal EPIs, U for vertical ones).
        n_epis: number of EPIs (H for horizontal, W for vertical).
        width: EPI width in pixels (W for horizontal, H for vertical).
        config: parameters.

    Returns:
        `EPISegments` of shape ``(n_epis, S)``.

    Raises:
        ValueError: on an unknown direction, fewer than 2 views, or a surface-vector array
            whose length differs from the edge set's capacity.

    Warns:
        UserWarning: when lines or segments were dropped for capacity.

    References:
        Thesis Sec. 4.2.1 (Alg. 2, eq 4.7).
    """
    if direction not in (HORIZONTAL, VERTICAL):
        raise ValueError(f"direction must be HORIZONTAL (0) or VERTICAL (1); got {direction}")
    if n_views < 2:
        raise ValueError(f"an EPI needs at least 2 views; got {n_views}")
    off = np.asarray(surface_offset)
    if off.shape != (edges.capacity, 2):
        raise ValueError(
            f"surface_offset must have shape ({edges.capacity}, 2) like the edge set; "
            f"got {off.shape}"
        )
    lines, dropped = _epi_lines(edges, off, direction, n_epis, config)
    all_d = np.concatenate([dd for _, dd, _ in lines]) if lines else np.zeros(0)
    fallback = float(np.median(all_d)) if all_d.size else 0.0
    S = config.segments_per_epi(width)
    table = np.zeros((n_epis, S, 10), np.float32)
    valid = np.zeros((n_epis, S), bool)
    for e, (p, d, s) in enumerate(lines):
        rows = match_lines(p, d, s, n_views, width, config, fallback)
        if rows.shape[0] > S:
            dropped += rows.shape[0] - S
            rows = rows[np.argsort(rows[:, 2] - rows[:, 0], kind="stable")[:S]]
        table[e, : rows.shape[0]] = rows
        valid[e, : rows.shape[0]] = True
    if dropped:
        warnings.warn(
            f"{dropped} EPI lines/segments dropped for capacity; raise "
            "SuperpixelConfig.line_capacity or segment_capacity",
            stacklevel=2,
        )
    t = jnp.asarray(table)
    return EPISegments(
        left_pos=t[..., 0],
        left_disp=t[..., 1],
        right_pos=t[..., 2],
        right_disp=t[..., 3],
        disparity=t[..., 4],
        known=t[..., 5] > 0.5,
        left_cut=t[..., 6] > 0.5,
        right_cut=t[..., 7] > 0.5,
        valid=jnp.asarray(valid),
        n_dropped=jnp.asarray(dropped, jnp.int32),
        surface_left=t[..., 8],
        surface_right=t[..., 9],
    )


def _spans(lp, ld, rp, rd, n_views: int, width: int):
    """First and one-past-last integer pixel ``(.., V, S)`` of every segment in every EPI row:
    ``left(t) <= x < right(t)`` is ``ceil(left) <= x < ceil(right)``, clipped to the EPI."""
    t = (jnp.arange(n_views) - n_views // 2).astype(jnp.float32)[:, None]
    left = lp[..., None, :] - t * ld[..., None, :]
    right = rp[..., None, :] - t * rd[..., None, :]
    x0 = jnp.clip(jnp.ceil(left), 0, width).astype(jnp.int32)
    x1 = jnp.clip(jnp.ceil(right), 0, width).astype(jnp.int32)
    return x0, x1


def _render_one(lp, ld, rp, rd, disp, known, valid, sl, sr, n_views: int, width: int, span: int):
    x0, x1 = _spans(lp, ld, rp, rd, n_views, width)  # (V, S)
    V, S = x0.shape
    xs = x0[..., None] + jnp.arange(span, dtype=jnp.int32)  # (V, S, K)
    cov = (xs < x1[..., None]) & valid[None, :, None]
    row = jnp.arange(V, dtype=jnp.int32)[:, None, None]
    tgt = jnp.where(cov, row * width + xs, V * width).ravel()  # V * width: dropped
    order = jnp.where(known, disp, disp - 1e4)  # unresolved segments lie behind the rest
    o = jnp.broadcast_to(order[None, :, None], cov.shape).ravel()
    z = jnp.full((V * width + 1,), -jnp.inf, order.dtype).at[tgt].max(o)
    win = cov.ravel() & (o >= z[tgt])
    sid = jnp.broadcast_to(jnp.arange(S, dtype=jnp.int32)[None, :, None], cov.shape).ravel()
    idx = jnp.full((V * width + 1,), S, jnp.int32).at[jnp.where(win, tgt, V * width)].min(sid)
    idx = idx[: V * width].reshape(V, width)
    hit = idx < S
    idx = jnp.where(hit, idx, 0)
    # the pixel's disparity: linear between the surface ends across the segment's row span
    t = (jnp.arange(V) - V // 2).astype(jnp.float32)[:, None]
    left = jnp.take_along_axis(lp[None, :] - t * ld[None, :], idx, axis=1)
    right = jnp.take_along_axis(rp[None, :] - t * rd[None, :], idx, axis=1)
    x = jnp.arange(width, dtype=jnp.float32)[None, :]
    f = jnp.clip((x - left) / jnp.maximum(right - left, 1e-6), 0.0, 1.0)
    d = sl[idx] + f * (sr[idx] - sl[idx])
    return jnp.where(hit, idx, -1), jnp.where(hit, d, 0.0)


@functools.partial(jax.jit, static_argnames=("n_views", "width", "span", "batch_size"))
def _render(args, n_views: int, width: int, span: int, batch_size: int):
    fn = lambda a: _render_one(*a, n_views=n_views, width=width, span=span)  # noqa: E731
    return jax.lax.map(fn, args, batch_size=batch_size)


def render_segments(
    segments: EPISegments, n_views: int, width: int, batch_size: int = 64
) -> tuple[Int[Array, "E V W"], Float[Array, "E V W"]]:
    """Label every EPI pixel with the nearest segment covering it.

    Pixel ``x`` of the row at view offset ``t`` is covered by a segment when
    ``left(t) <= x < right(t)`` with ``left(t) = left_pos - t left_disp`` (likewise right);
    among covering segments the largest disparity wins (the nearest surface occludes; ties:
    the lowest segment index); segments whose disparity is not ``known`` lie behind all known
    ones.

    Every segment paints its pixel span of every row into a z-buffer (two scatters, max of
    the depth order then min of the index among the winners), jitted and mapped over EPIs in
    batches. The widest span (read on the host, rounded up to a coarse ladder) is a static
    size, so the cost is ``O(E V S span)`` rather than ``O(E V S width)``.

    Args:
        segments: `EPISegments` ``(E, S)``.
        n_views: EPI height (views).
        width: EPI width (pixels).
        batch_size: EPIs per vectorised batch (bounds memory: ``batch · V · S · span``
            indices).

    Returns:
        ``(labels (E, V, W) int32`` segment index in ``[0, S)`` or -1 where uncovered,
        ``disparity (E, V, W) float32`` of that segment, 0 where uncovered).

    References:
        Thesis Sec. 4.2.1 (regions bounded by two lines with explicit depth order).
    """
    args = (
        segments.left_pos,
        segments.left_disp,
        segments.right_pos,
        segments.right_disp,
        segments.disparity,
        segments.known,
        segments.valid,
        segments.disparity if segments.surface_left is None else segments.surface_left,
        segments.disparity if segments.surface_right is None else segments.surface_right,
    )
    x0, x1 = _spans(*args[:4], n_views, width)
    widest = int(jnp.max(jnp.where(segments.valid[:, None, :], x1 - x0, 0), initial=0))
    span = 8
    while span < widest:
        span = span * 3 // 2 if span & (span - 1) == 0 else span * 4 // 3
    return _render(args, n_views=n_views, width=width, span=span, batch_size=batch_size)


def resolve_unknown(
    segments: EPISegments,
    labels: Int[Array, "E n w"],
    other_disparity: Float[Array, "E w"],
    other_known: Array,
    floor: float,
) -> EPISegments:
    """Disparity of the segments whose surface lies behind both bounding lines.

    Such a segment takes the mean disparity that the other EPI direction gives its pixels on
    the centre row (where that direction's segment is known). A segment no known pixel
    covers lies behind both its lines in both directions and takes ``floor`` (the scene's
    deepest disparity).

    Args:
        segments: `EPISegments` ``(E, S)`` of one direction.
        labels: ``(E, n, w)`` its rendered segment labels (`render_segments`).
        other_disparity: ``(E, w)`` the other direction's disparity on this direction's EPI
            centre rows (the centre view, transposed as needed).
        other_known: ``(E, w)`` bool, where ``other_disparity`` is known.
        floor: disparity of last resort (pixels per view step), e.g. the scene's deepest.

    Returns:
        The segments with resolved disparities (``known`` set where resolved from the other
        direction).

    References:
        Thesis Sec. 4.2.1 (segments regularised across the horizontal and vertical EPIs).
    """
    lab = np.asarray(labels)
    E, n, _ = lab.shape
    S = segments.valid.shape[1]
    centre = lab[:, n // 2]
    od, ok = np.asarray(other_disparity, np.float64), np.asarray(other_known)
    ids = np.where((centre >= 0) & ok, np.arange(E)[:, None] * S + centre, E * S).ravel()
    cnt = np.bincount(ids, minlength=E * S + 1)[:-1].reshape(E, S)
    tot = np.bincount(ids, od.ravel(), minlength=E * S + 1)[:-1].reshape(E, S)
    d = np.asarray(segments.disparity, np.float64).copy()
    known = np.asarray(segments.known).copy()
    valid = np.asarray(segments.valid)
    todo = valid & ~known
    got = todo & (cnt > 0)
    d[got] = tot[got] / cnt[got]
    d[todo & ~got] = np.minimum(floor, d[todo & ~got])
    known = known | got
    return segments.with_disparity(jnp.asarray(d, jnp.float32), jnp.asarray(known))
