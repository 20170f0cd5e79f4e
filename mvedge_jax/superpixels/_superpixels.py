"""View-consistent 4D light-field superpixels (thesis Ch. 5) and the k-means baseline."""

from __future__ import annotations

import functools
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from sklearn.cluster import KMeans

from .._pad import edge_pad
from ..edges import HORIZONTAL, VERTICAL, EdgeSet, detect_edges
from ..lightfield import LightField, rgb_to_lab
from ..metrics import centroid_deviation_from_sums
from ..surface import surface_vectors
from ._config import SEED_SHIFTS, SuperpixelConfig
from ._label import forward_labels, nearest_fill, propagate_labels
from ._segment import EPISegments, render_segments, resolve_unknown, segment_epis


class SuperpixelResult(eqx.Module):
    """Output of `superpixels` and `kmeans_superpixels`.

    Attributes:
        labels: ``(U, V, H, W)`` int32 superpixel label of every pixel of every view (the
            same label means the same superpixel in every view).
        disparity: ``(U, V, H, W)`` float32 disparity of every pixel (pixels per view step):
            the EPI segments' piece-wise disparity, or the dense ``disparity`` passed to
            `superpixels`, or the baseline's projected centre map.
        n_superpixels: number of k-means clusters (seeds on a regular grid of about
            ``H W / size²`` cells).
        consistent_fraction: fraction of all light-field pixels on which the projected
            horizontal and vertical segmentations agree (before the centre-view check and
            propagation; with a dense ``disparity`` and for the baseline: 1 minus the
            projection holes).
        seconds: wall seconds per stage (after compilation of the jitted stages is included
            on a first call; see ``experiments/superpixels_ch5.py`` for timings).
    """

    labels: Int[Array, "U V H W"]
    disparity: Float[Array, "U V H W"]
    n_superpixels: int = eqx.field(static=True)
    consistent_fraction: float = eqx.field(static=True)
    seconds: dict = eqx.field(static=True)


def _check_lf(lf: LightField) -> None:
    U, V = lf.grid
    if U < 3 or V < 3:
        raise ValueError(f"superpixels need at least 3x3 views; got a {U}x{V} grid")
    if not bool(jnp.isfinite(lf.views).all()):
        raise ValueError(f"light field {lf.name!r} contains NaN or Inf pixel values")
    if not bool(
        np.asarray(lf.view_mask)[U // 2].all() and np.asarray(lf.view_mask)[:, V // 2].all()
    ):
        raise ValueError("superpixels need the complete central row and column of views")


def _trim(seg: EPISegments, multiple: int = 16) -> EPISegments:
    """The same segments with the capacity cut to the largest per-EPI count (rounded up to a
    ``multiple``, which bounds recompilation): the valid segments of an EPI come first, so
    segment indices are unchanged and rendering costs ``O(S)`` less."""
    S = seg.valid.shape[1]
    n = int(np.asarray(seg.valid).sum(1).max(initial=0))
    keep = min(S, max(multiple, -(-n // multiple) * multiple))
    return jax.tree_util.tree_map(lambda a: a[:, :keep] if a.ndim == 2 else a, seg)


@jax.jit
def _segment_colours(epi_lab, labels, n_segments_dummy):
    """Mean CIELAB and pixel count per segment: ``(E, S, 3)``, ``(E, S)``."""
    E, S = n_segments_dummy.shape
    ids = jnp.where(labels >= 0, jnp.arange(E)[:, None, None] * S + labels, E * S).ravel()
    cnt = jax.ops.segment_sum(jnp.ones_like(ids, jnp.float32), ids, E * S + 1)[:-1]
    tot = jax.ops.segment_sum(epi_lab.reshape(-1, 3), ids, E * S + 1)[:-1]
    mean = tot / jnp.maximum(cnt, 1.0)[:, None]
    return mean.reshape(E, S, 3), cnt.reshape(E, S)


@jax.jit
def _known_map(known, centre_labels):
    """``(E, w)`` bool: the EPI centre-row pixel's segment has a known disparity."""
    k = jnp.take_along_axis(known, jnp.maximum(centre_labels, 0), axis=1)
    return (centre_labels >= 0) & k


@jax.jit
def _cluster_maps(table, seg_labels):
    """EPI segment labels ``(E, n, w)`` → cluster labels via ``table (E, S)`` (-1 stays)."""
    E = seg_labels.shape[0]
    flat = jnp.maximum(seg_labels, 0).reshape(E, -1)
    out = jnp.take_along_axis(table, flat, axis=1).reshape(seg_labels.shape)
    return jnp.where(seg_labels >= 0, out, -1)


def _uniform_seeds(H: int, W: int, k: int, shift: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """``(k', 2)`` (x, y) seeds on a regular grid of about ``k`` cells (SLIC's seeding), moved
    by ``shift = (sx, sy)`` grid cells and clipped into the image."""
    step = np.sqrt(H * W / k)
    ny, nx = max(1, round(H / step)), max(1, round(W / step))
    ys = np.clip((np.arange(ny) + 0.5 + shift[1]) * H / ny - 0.5, 0, H - 1)
    xs = np.clip((np.arange(nx) + 0.5 + shift[0]) * W / nx - 0.5, 0, W - 1)
    gy, gx = np.meshgrid(ys, xs, indexing="ij")
    return np.stack([gx.ravel(), gy.ravel()], -1)


def _kmeans(
    xy: np.ndarray,
    feats: np.ndarray,
    H: int,
    W: int,
    k: int,
    iters: int,
    shift: tuple[float, float] = (0.0, 0.0),
) -> tuple[np.ndarray, int]:
    """scikit-learn k-means of weighted ``feats (N, F)`` from about ``k`` uniform seeds moved
    by ``shift`` grid cells (each takes the features of the point nearest to it in the image;
    duplicates merged); returns the labels and the number of clusters."""
    seeds = _uniform_seeds(H, W, k, shift)
    _, nearest = cKDTree(xy).query(seeds)
    init = np.unique(feats[nearest], axis=0)
    init = init[: feats.shape[0]]
    km = KMeans(n_clusters=init.shape[0], init=init, n_init=1, max_iter=iters, algorithm="lloyd")
    return km.fit_predict(feats).astype(np.int32), int(init.shape[0])


def _disparity_scale(lf: LightField, d: np.ndarray) -> tuple[float, float]:
    if lf.disparity_range is not None:
        lo, hi = lf.disparity_range
    elif d.size:
        lo, hi = float(np.percentile(d, 1)), float(np.percentile(d, 99))
    else:
        lo, hi = 0.0, 1.0
    return float(lo), float(max(hi - lo, 1e-3))


def _features(x, y, d, lab, lo, span, config: SuperpixelConfig) -> np.ndarray:
    dn = (np.asarray(d, np.float64) - lo) / span
    return np.concatenate(
        [
            config.weight_xy * np.stack([x, y], -1),
            config.weight_d * dn[:, None],
            config.weight_lab * config.lab_scale * np.asarray(lab, np.float64),
        ],
        axis=1,
    )


def _project_both(row_l, row_d, col_l, col_d):
    """Every view's labels from the centre row of views (view ``(r_c, c)`` shifted by
    ``dr = r - r_c``) and from the centre column (view ``(r, c_c)`` shifted by ``dc``)."""
    V, U = row_l.shape[0], col_l.shape[0]
    rs = (jnp.arange(U) - U // 2).astype(jnp.float32)
    cs = (jnp.arange(V) - V // 2).astype(jnp.float32)
    lh, dh = jax.vmap(
        lambda dr: jax.vmap(lambda lb, d: forward_labels(lb, d, dr, 0.0))(row_l, row_d)
    )(rs)
    lv, dv = jax.vmap(lambda lb, d: jax.vmap(lambda dc: forward_labels(lb, d, 0.0, dc))(cs))(
        col_l, col_d
    )
    return lh, dh, lv, dv  # each (U, V, H, W)


@functools.partial(jax.jit, static_argnames=("keep",))
def _project_agree(row_l, row_d, col_l, col_d, keep: bool = False):
    """Labels ``(U, V, H, W)`` of every view from both segmentations, kept where they agree
    (with ``keep``, a disagreeing pixel keeps the nearer segmentation's label, the horizontal
    on ties); their disparities; and the bool mask of agreeing pixels."""
    lh, dh, lv, dv = _project_both(row_l, row_d, col_l, col_d)
    agree = (lh >= 0) & (lh == lv)
    lab = jnp.where(agree, lh, -1)
    d = jnp.where(agree, 0.5 * (dh + dv), 0.0)
    if keep:
        use_v = (lv >= 0) & ((lh < 0) | (dv > dh))
        lab = jnp.where(agree, lab, jnp.where(use_v, lv, lh))
        d = jnp.where(agree, d, jnp.where(use_v, dv, dh))
    return lab, d, agree


@jax.jit
def _fill_from_cross(labels, disp, row_l, row_d, col_l, col_d):
    """Fill unlabelled pixels of every view from the (propagated) cross-hair views."""
    lh, dh, lv, dv = _project_both(row_l, row_d, col_l, col_d)
    take_h = (labels < 0) & (lh >= 0)
    labels = jnp.where(take_h, lh, labels)
    disp = jnp.where(take_h, dh, disp)
    take_v = (labels < 0) & (lv >= 0)
    return jnp.where(take_v, lv, labels), jnp.where(take_v, dv, disp)


def _view_offsets(U: int, V: int) -> np.ndarray:
    """``(U V, 2)`` float32 ``(dr, dc)`` of every view relative to the centre, row-major."""
    rs, cs = np.meshgrid(np.arange(U) - U // 2, np.arange(V) - V // 2, indexing="ij")
    return np.stack([rs.ravel(), cs.ravel()], -1).astype(np.float32)


@jax.jit
def _project_centre(centre_l, centre_d, offsets):
    """Centre labels ``(H, W)`` forward-projected (z-buffered) with the centre disparity into
    the views at ``offsets (K, 2)``: ``(labels, disparity)`` of shape ``(K, H, W)``."""
    return jax.vmap(lambda o: forward_labels(centre_l, centre_d, o[0], o[1]))(offsets)


def _centre_visibility(centre_d: Float[ArrayLike, "H W"], U: int, V: int) -> csr_matrix:
    """``(U V, H W)`` sparse counts: how many pixels of view ``(r, c)`` (row-major) show each
    centre-view pixel when the centre view is forward-projected (z-buffered, nearer wins)
    with its disparity ``centre_d`` (pixels per view step). A centre pixel hidden or moved
    out of the frame in a view counts 0 there."""
    centre_d = jnp.asarray(centre_d, jnp.float32)
    H, W = centre_d.shape
    index = jnp.arange(H * W, dtype=jnp.int32).reshape(H, W)
    seen, _ = _project_centre(index, centre_d, jnp.asarray(_view_offsets(U, V)))
    seen = np.asarray(seen).reshape(U * V, H * W)
    ok = seen >= 0
    indptr = np.concatenate([[0], np.cumsum(ok.sum(1))])
    return csr_matrix((np.ones(int(indptr[-1])), seen[ok], indptr), shape=(U * V, H * W))


def _predicted_self_similarity(
    centre_labels: Int[ArrayLike, "H W"], visibility: csr_matrix
) -> float:
    """The self-similarity error that centre-view superpixels would have if every view
    showed exactly the centre pixels that `_centre_visibility` finds visible there, with
    their labels (a pixel moved back into the centre view lands on its source): per
    superpixel, the mean distance of its per-view centroids from their mean; mean over
    superpixels (pixels). The pixels that only other views see (disocclusions, the frame's
    new strips) are not counted. Not in the thesis: the score `superpixels` uses to choose
    its seed grid (``SuperpixelConfig.seed_candidates``)."""
    H, W = np.shape(centre_labels)
    _, lab = np.unique(np.asarray(centre_labels).ravel(), return_inverse=True)
    n = int(lab.max()) + 1
    y, x = np.divmod(np.arange(H * W, dtype=np.float64), W)
    # one sparse product gives every view's pixel count and coordinate sums per label
    cols = np.stack([lab, lab + n, lab + 2 * n], 1).ravel()
    data = np.stack([np.ones(H * W), x, y], 1).ravel()
    member = csr_matrix((data, cols, np.arange(0, 3 * H * W + 1, 3)), shape=(H * W, 3 * n))
    sums = (visibility @ member).toarray().T
    dev, views = centroid_deviation_from_sums(sums[:n], sums[n : 2 * n], sums[2 * n :])
    keep = views > 0
    return float(np.mean(dev[keep] / views[keep])) if keep.any() else 0.0


def _most_consistent(shifts, candidate, score):
    """The candidate partition ``candidate(shift)`` of the seed grid with the lowest
    ``score(candidate)`` (the first on ties); with one grid, that grid's without scoring."""
    best_score, best = np.inf, None
    for shift in shifts:
        cand = candidate(shift)
        if len(shifts) == 1:
            return cand
        value = score(cand)
        if value < best_score:
            best_score, best = value, cand
    return best


def _look_back(disparity, dr, dc):
    """Nearest centre-view pixel ``(cy, cx)`` (clipped into the image) of every pixel of views
    at offsets ``dr, dc`` (broadcast against ``disparity (..., H, W)``) moved back to the
    centre by its own disparity, and whether it lies inside the image."""
    H, W = disparity.shape[-2:]
    y = jnp.arange(H, dtype=jnp.float32)[:, None]
    x = jnp.arange(W, dtype=jnp.float32)[None, :]
    cy = jnp.rint(y + dr * disparity).astype(jnp.int32)
    cx = jnp.rint(x + dc * disparity).astype(jnp.int32)
    inside = (cy >= 0) & (cy < H) & (cx >= 0) & (cx < W)
    return jnp.clip(cy, 0, H - 1), jnp.clip(cx, 0, W - 1), inside


@jax.jit
def _project_resolve(row_l, row_d, col_l, col_d, centre_l, centre_d):
    """Labels of every view from both segmentations, checked against the fully labelled
    centre view ``(H, W)``, and holes filled from it.

    A projected label of view ``(r, c)`` *matches* when it is the centre view's label at the
    pixel moved back to the centre by the label's own disparity (nearest pixel, inside the
    image). A pixel where the two segmentations agree keeps the label if either projection
    matches (disparity: their mean); otherwise it keeps the label of the matching one (both:
    the nearer, i.e. the larger disparity); else it is a hole. Holes take the centre labels
    forward-projected (z-buffered) by the centre disparity, where one lands. Returns
    ``labels`` (-1: hole), ``disparity`` ``(U, V, H, W)`` and the bool mask of pixels where
    the two segmentations agree.
    """
    lh, dh, lv, dv = _project_both(row_l, row_d, col_l, col_d)
    U, V = lh.shape[:2]
    agree = (lh >= 0) & (lh == lv)
    off = _view_offsets(U, V)
    dr = off[:, 0].reshape(U, V, 1, 1)
    dc = off[:, 1].reshape(U, V, 1, 1)

    def matches(lab, d):
        cy, cx, inside = _look_back(d, dr, dc)
        return (lab >= 0) & inside & (centre_l[cy, cx] == lab)

    mh, mv = matches(lh, dh), matches(lv, dv)
    use_v = mv & (~mh | (dv > dh))
    keep = agree & (mh | mv)
    lab = jnp.where(keep, lh, jnp.where(use_v, lv, jnp.where(mh, lh, -1)))
    d = jnp.where(keep, 0.5 * (dh + dv), jnp.where(use_v, dv, jnp.where(mh, dh, 0.0)))
    pl, pd = _project_centre(centre_l, centre_d, jnp.asarray(off))
    pl, pd = pl.reshape(lab.shape), pd.reshape(lab.shape)
    take = (lab < 0) & (pl >= 0)
    return jnp.where(take, pl, lab), jnp.where(take, pd, d), agree


@jax.jit
def _project_dense(centre_l, disparity, tol):
    """Centre labels ``(H, W)`` into every view with a dense per-view disparity
    ``(U, V, H, W)`` (pixels per view step; not in the thesis).

    First the centre labels forward-projected with the centre view's disparity, z-buffered
    (nearer wins), as the k-means baseline does. A pixel no projection reaches (a crack of the
    rounding, or a disocclusion) then looks back into the centre view with its own view's
    disparity ``d``: it takes the centre label there when the centre disparity at that pixel is
    within ``tol`` of ``d`` (the same surface, visible in the centre view); else it stays a
    hole (-1). Returns ``labels (U, V, H, W)`` int32 and the bool mask of labelled pixels.
    """
    U, V, H, W = disparity.shape
    centre_d = disparity[U // 2, V // 2]
    off = _view_offsets(U, V)
    pl, _ = _project_centre(centre_l, centre_d, jnp.asarray(off))
    pl = pl.reshape(U, V, H, W)
    cy, cx, inside = _look_back(
        disparity, off[:, 0].reshape(U, V, 1, 1), off[:, 1].reshape(U, V, 1, 1)
    )
    seen = inside & (jnp.abs(centre_d[cy, cx] - disparity) <= tol)
    back = jnp.where(seen, centre_l[cy, cx], -1)
    labels = jnp.where(pl >= 0, pl, back)
    return labels, labels >= 0


@functools.partial(jax.jit, static_argnames=("radius",))
def _mode_filter(labels: Int[Array, "H W"], radius: int) -> Int[Array, "H W"]:
    """Majority label in the ``(2 radius + 1)²`` window of every pixel (edge-padded); a pixel
    keeps its own label unless another one is strictly more frequent (ties among the others:
    the first in row-major window order)."""
    H, W = labels.shape
    p = edge_pad(labels, radius)
    side = 2 * radius + 1
    win = [p[i // side : i // side + H, i % side : i % side + W] for i in range(side * side)]

    def count(a):
        return sum((a == b).astype(jnp.int32) for b in win)

    best, best_n = labels, count(labels)
    for a in win:
        n = count(a)
        better = n > best_n
        best, best_n = jnp.where(better, a, best), jnp.where(better, n, best_n)
    return best


@functools.partial(jax.jit, static_argnames=("n_labels", "iters", "radius"))
def _refine_centre(
    labels: Int[Array, "H W"],
    feats: Float[Array, "H W F"],
    n_labels: int,
    iters: int,
    radius: int,
) -> Int[Array, "H W"]:
    """Local k-means of the centre view's pixels from given labels (SLIC-style; not in the
    thesis).

    Every iteration re-estimates each label's centre (the mean of ``feats`` over its pixels),
    then moves every pixel to the nearest centre (squared Euclidean distance in ``feats``)
    among the labels at the 17 offsets ``{-1, 0, 1}² ∪ {-radius, 0, radius}²`` around it
    (edge-padded; its own label included). A label whose pixels all leave keeps no centre and
    cannot return.

    Args:
        labels: ``(H, W)`` int32 labels in ``[0, n_labels)``.
        feats: ``(H, W, F)`` float32 weighted pixel features (`_features`: x, y, normalised
            disparity, CIELAB).
        n_labels: static number of labels.
        iters: static number of iterations.
        radius: static candidate distance (pixels, chessboard).

    Returns:
        ``(H, W)`` int32 labels in ``[0, n_labels)``.
    """
    H, W, F = feats.shape
    r = max(int(radius), 1)
    offs = sorted({(a * s, b * s) for s in (1, r) for a in (-1, 0, 1) for b in (-1, 0, 1)})
    flat_f = feats.reshape(-1, F)

    def body(_, lab):
        ids = lab.ravel()
        cnt = jax.ops.segment_sum(jnp.ones((H * W,), jnp.float32), ids, n_labels)
        tot = jax.ops.segment_sum(flat_f, ids, n_labels)
        centres = tot / jnp.maximum(cnt, 1.0)[:, None]
        p = edge_pad(lab, r)
        best, best_d = lab, jnp.sum((feats - centres[lab]) ** 2, -1)
        for dy, dx in offs:
            cand = p[r + dy : r + dy + H, r + dx : r + dx + W]
            dist = jnp.sum((feats - centres[cand]) ** 2, -1)
            better = dist < best_d
            best, best_d = jnp.where(better, cand, best), jnp.where(better, dist, best_d)
        return best

    return jax.lax.fori_loop(0, iters, body, labels)


def _fragments(labels: np.ndarray) -> np.ndarray:
    """``(H, W)`` bool: the pixels outside the largest 4-connected piece of their label (SciPy
    connected components of the graph of equal-label neighbours; ties: the first piece)."""
    H, W = labels.shape
    idx = np.arange(H * W).reshape(H, W)
    right = labels[:, :-1] == labels[:, 1:]
    down = labels[:-1] == labels[1:]
    a = np.concatenate([idx[:, :-1][right], idx[:-1][down]])
    b = np.concatenate([idx[:, 1:][right], idx[1:][down]])
    graph = coo_matrix((np.ones(a.size, np.int8), (a, b)), shape=(H * W, H * W))
    n, piece = connected_components(graph, directed=False)
    size = np.bincount(piece, minlength=n)
    piece_label = np.zeros(n, np.int64)
    piece_label[piece] = labels.ravel()
    order = np.lexsort((-size, piece_label))  # by label, the largest piece first
    first = np.ones(n, bool)
    first[1:] = piece_label[order][1:] != piece_label[order][:-1]
    keep = np.zeros(n, bool)
    keep[order[first]] = True
    return ~keep[piece].reshape(H, W)


def _refine_centre_dense(c_l, lab_c, d_c, lo, span, k, config):
    """`_refine_centre` of the centre labels ``c_l (1, H, W)`` int32 in ``[0, k)`` on the
    features of `_features` per pixel: x, y (pixels), the dense centre disparity ``d_c (H, W)``
    (pixels per view step) normalised by ``lo`` and ``span``, and the centre CIELAB
    ``lab_c (H, W, 3)`` (L* in [0, 100]); returns ``(1, H, W)`` int32."""
    H, W = d_c.shape
    y, x = np.mgrid[0:H, 0:W]
    flat = _features(
        x.ravel(), y.ravel(), np.ravel(d_c), np.reshape(lab_c, (-1, 3)), lo, span, config
    )
    feats = jnp.asarray(flat.reshape(H, W, -1), jnp.float32)
    radius = config.refine_radius or max(1, round(config.size / 2))
    return _refine_centre(c_l[0], feats, int(k), config.refine_iters, radius)[None]


def _cross_offsets(U: int, V: int) -> np.ndarray:
    rc, cc = U // 2, V // 2
    row = [(0.0, float(c - cc)) for c in range(V)]
    col = [(float(r - rc), 0.0) for r in range(U)]
    return np.asarray(row + col, np.float32)


def _ends(lab_row: Array, lab_col: Array) -> tuple[Array, Array]:
    """CIELAB ``(4, H, W, 3)`` and offsets ``(4, 2)`` of the four end views of the cross-hair
    (eq 5.1's comparison) from the centre row ``(V, H, W, 3)`` and column ``(U, H, W, 3)``."""
    V, U = lab_row.shape[0], lab_col.shape[0]
    rc, cc = U // 2, V // 2
    lab = jnp.stack([lab_row[0], lab_row[V - 1], lab_col[0], lab_col[U - 1]])
    idx = [(rc, 0), (rc, V - 1), (0, cc), (U - 1, cc)]
    off = jnp.asarray([(r - rc, c - cc) for r, c in idx], jnp.float32)
    return lab, off


def _propagate(config, lab, labels, disp, offsets, cmp_lab, cmp_off, *, w_photo=None):
    """`propagate_labels` (eq 5.1) with the weights, radius and passes of ``config``
    (``w_photo`` overrides ω_d)."""
    return propagate_labels(
        lab,
        labels,
        disp,
        offsets,
        cmp_lab,
        cmp_off,
        config.w_colour,
        config.w_spatial,
        config.w_photo if w_photo is None else w_photo,
        radius=config.propagation_radius,
        passes=config.propagation_passes,
    )


def _centre_labels(
    config, row_l, row_d, col_l, col_d, lab_c, cmp_lab, cmp_off, dense_c, lo, span, k
):
    """The centre view's complete labels and disparity ``(1, H, W)`` (``centre_first``): the
    pixels where the centre row's and column's cluster maps agree, eq 5.1 propagation and
    nearest fill; with a dense centre disparity ``dense_c (H, W)`` and ``refine_iters``, the
    local k-means refinement; the majority filter; the connectivity step."""
    V, U = row_l.shape[0], col_l.shape[0]
    rc, cc = U // 2, V // 2
    c_ok = (row_l[cc] >= 0) & (row_l[cc] == col_l[rc])
    c_l = jnp.where(c_ok, row_l[cc], -1)[None]
    c_d = jnp.where(c_ok, 0.5 * (row_d[cc] + col_d[rc]), 0.0)[None]
    c_l, c_d = _propagate(
        config, lab_c[None], c_l, c_d, jnp.zeros((1, 2), jnp.float32), cmp_lab, cmp_off
    )
    c_l, c_d = nearest_fill(c_l, c_d)
    if dense_c is not None and config.refine_iters > 0:
        c_l = _refine_centre_dense(c_l, lab_c, dense_c, lo, span, k, config)
    if config.smooth_radius > 0:
        c_l = _mode_filter(c_l[0], config.smooth_radius)[None]
    if config.connected:
        frag = _fragments(np.asarray(c_l[0]))
        c_l, c_d = nearest_fill(jnp.where(frag, -1, c_l), c_d)
    return c_l, c_d


def superpixels(
    lf: LightField,
    config: SuperpixelConfig = SuperpixelConfig(),
    *,
    edges: EdgeSet | None = None,
    surface_offset: Float[ArrayLike, "N 2"] | None = None,
    disparity: Float[ArrayLike, "U V H W"] | None = None,
) -> SuperpixelResult:
    """View-consistent superpixels of every view of a light field (thesis Ch. 5).

    1. Occlusion-aware EPI segmentation (Sec. 4.2.1): the lines of every horizontal EPI (centre
       row of views) and vertical EPI (centre column) are paired into depth-ordered segments
       (`segment_epis`, Alg. 2) and rendered into EPI label maps (`render_segments`); a segment
       whose bounding lines both face away from it (a surface seen between two nearer ones)
       takes the other direction's disparity on the centre view (`resolve_unknown`). With
       ``config.slant_tol > 0`` a segment's disparity varies linearly between bounding lines
       that lie on its surface, so every EPI pixel has its own disparity.
    2. Clustering (Sec. 5.1.1): every segment with at least one visible pixel becomes a point
       ``(x, y, d, L*, a*, b*)`` (x, y: its centre on the centre view; d: its disparity,
       normalised to [0, 1] over the scene's range; colour: the mean CIELAB of its EPI
       pixels), weighted by ``weight_xy, weight_xy, weight_d, weight_lab · lab_scale``;
       scikit-learn k-means from ``round(H W / size²)`` uniform seeds (each seed takes the
       features of the segment nearest to it in the image). With ``config.centre_first``
       and ``config.seed_candidates > 1`` (default 6; not in the thesis) this runs from
       that many shifted seed grids, the centre view of each is labelled (step 3), and the
       partition with the lowest predicted self-similarity error is kept
       (`_predicted_self_similarity`: the centre labels moved into every view with the
       centre disparity, the dense ``disparity`` if given, else the segments'; no ground
       truth).
    3. Every view ``(r, c)`` receives the cluster labels of the horizontal segmentation of view
       ``(r_c, c)`` shifted vertically and of the vertical segmentation of view ``(r, c_c)``
       shifted horizontally, by their pixels' disparities (z-buffer: nearer wins).
       With ``config.centre_first`` (default, not in the thesis) the centre view is labelled
       completely first (agreeing pixels, eq 5.1, nearest fill; then a majority filter of
       chessboard radius ``config.smooth_radius``; with ``config.connected`` each label
       then keeps only its largest 4-connected piece, the rest refilled by nearest fill);
       a projected label is kept
       in any view only where it equals the centre's label at the pixel moved back to the
       centre by its disparity (a disagreement takes the segmentation that matches, both:
       the nearer), and the remaining pixels take the centre labels forward-projected.
       With a dense ``disparity`` the centre labels are instead projected with it (see
       ``disparity`` below).
       Otherwise (the thesis) pixels where the two disagree are unlabelled (with
       ``config.keep_disagreeing`` they keep the nearer one's label instead).
    4. Label propagation (eq 5.1) on the cross-hair views for what is still unlabelled,
       projection of those labels into the other views' unlabelled pixels, and
       nearest-labelled-pixel fill for the rest: every pixel of every view gets a label and
       a disparity.

    The EPI pairing, k-means and the centre view's connected components run on the host
    (SciPy / scikit-learn); rendering, projection and propagation are jitted and vectorised
    over EPIs and views.

    Args:
        lf: the light field (at least 3x3 views, complete cross-hair).
        config: parameters.
        edges: a multi-view edge set of ``lf`` (`detect_edges`); detected with
            ``config.edges`` when omitted.
        surface_offset: ``(N, 2)`` surface vectors of ``edges`` (`surface_vectors` ``.offset``);
            computed with ``config.surface`` when omitted.
        disparity: optional ``(U, V, H, W)`` float dense disparity of every view, pixels per
            view step (the Ch. 6 reconstruction, `estimate_disparity` ``.disparity``, built
            from the same edges). Given and with ``config.centre_first``, step 3 changes (not
            in the thesis): the completed centre labels are projected into every view with
            it instead of the EPI segments' piece-wise disparity (`_project_dense`: the
            centre labels forward-projected with the centre map, z-buffered, as the k-means
            baseline; unreached pixels look back into the centre view with their own view's
            disparity and take its label where the centre disparity there is within
            ``config.dense_tol``); the remaining holes are filled as in step 4, and the
            returned ``disparity`` is this input. With ``config.refine_iters > 0`` the
            completed centre labels first pass that many iterations of a local k-means of
            the centre pixels on the clustering's features with this map's centre view as
            ``d`` (`_refine_centre`), before the majority filter. Ignored with
            ``centre_first=False``.

    Returns:
        A `SuperpixelResult` with ``labels`` and ``disparity`` of shape ``(U, V, H, W)``.

    Raises:
        ValueError: fewer than 3x3 views, an incomplete cross-hair, NaN/Inf pixels,
            ``surface_offset`` of the wrong shape, ``disparity`` not ``(U, V, H, W)`` or not
            finite, or no EPI segment at all.

    References:
        Thesis Sec. 4.2.1 (Alg. 2, eq 4.7), Sec. 5.1 (clustering, eq 5.1); Khan et al.,
        "View-consistent 4D light field superpixel segmentation", ICCV 2019.
    """
    _check_lf(lf)
    U, V = lf.grid
    H, W = lf.size
    rc, cc = U // 2, V // 2
    if disparity is not None:
        disparity = jnp.asarray(disparity, jnp.float32)
        if disparity.shape != (U, V, H, W):
            raise ValueError(f"disparity must have shape {(U, V, H, W)}; got {disparity.shape}")
        if not bool(jnp.isfinite(disparity).all()):
            raise ValueError("disparity contains NaN or Inf")
    seconds: dict[str, float] = {}
    t0 = time.perf_counter()
    if edges is None:
        edges = detect_edges(lf, config.edges)
        jax.block_until_ready(edges)
        seconds["edges"] = time.perf_counter() - t0
        t0 = time.perf_counter()
    if surface_offset is None:
        surface_offset = surface_vectors(edges, lf.centre_view, config.surface).offset
        surface_offset = jax.block_until_ready(surface_offset)
        seconds["surface"] = time.perf_counter() - t0
        t0 = time.perf_counter()
    seg_h = segment_epis(edges, surface_offset, HORIZONTAL, V, H, W, config)
    seg_v = segment_epis(edges, surface_offset, VERTICAL, U, W, H, config)
    seg_h, seg_v = _trim(seg_h), _trim(seg_v)
    seconds["pairing"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    lab_h, disp_h = render_segments(seg_h, n_views=V, width=W)  # (H, V, W)
    lab_v, disp_v = render_segments(seg_v, n_views=U, width=H)  # (W, U, H)
    # Segments behind both their lines take the other direction's centre-view disparity.
    kh = _known_map(seg_h.known, lab_h[:, V // 2])  # (H, W)
    kv = _known_map(seg_v.known, lab_v[:, U // 2])  # (W, H)
    lines_d = np.asarray(edges.disparity)[np.asarray(edges.valid)]
    # The deepest surface seen: the 2nd percentile of the line disparities.
    floor = (
        float(np.percentile(lines_d, 2))
        if lines_d.size
        else lf.disparity_range[0]
        if lf.disparity_range is not None
        else 0.0
    )
    seg_h, seg_v = (
        resolve_unknown(seg_h, lab_h, disp_v[:, U // 2].T, kv.T, floor),
        resolve_unknown(seg_v, lab_v, disp_h[:, V // 2].T, kh.T, floor),
    )
    lab_h, disp_h = render_segments(seg_h, n_views=V, width=W)
    lab_v, disp_v = render_segments(seg_v, n_views=U, width=H)
    lab_row = rgb_to_lab(lf.views[rc])  # (V, H, W, 3): only the cross-hair is needed
    lab_col = rgb_to_lab(lf.views[:, cc])  # (U, H, W, 3)
    epi_h = jnp.transpose(lab_row, (1, 0, 2, 3))  # (H, V, W, 3)
    epi_v = jnp.transpose(lab_col, (2, 0, 1, 3))  # (W, U, H, 3)
    col_h, cnt_h = _segment_colours(epi_h, lab_h, seg_h.disparity)
    col_v, cnt_v = _segment_colours(epi_v, lab_v, seg_v.disparity)
    jax.block_until_ready((col_h, col_v))
    seconds["render"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    feats, xys, where = [], [], []
    for seg, col, cnt, direction in ((seg_h, col_h, cnt_h, 0), (seg_v, col_v, cnt_v, 1)):
        ok = np.asarray(seg.valid) & (np.asarray(cnt) > 0)
        e, s = np.nonzero(ok)
        mid = 0.5 * (np.asarray(seg.left_pos)[e, s] + np.asarray(seg.right_pos)[e, s])
        x, y = (mid, e.astype(np.float64)) if direction == 0 else (e.astype(np.float64), mid)
        x = np.clip(x, 0, W - 1)
        y = np.clip(y, 0, H - 1)
        xys.append(np.stack([x, y], -1))
        feats.append((x, y, np.asarray(seg.disparity)[e, s], np.asarray(col)[e, s]))
        where.append((e, s))
    xy = np.concatenate(xys)
    if xy.shape[0] == 0:
        raise ValueError(f"no EPI segment found in light field {lf.name!r}")
    d_all = np.concatenate([f[2] for f in feats])
    lo, span = _disparity_scale(lf, d_all)
    F = np.concatenate([_features(*f, lo, span, config) for f in feats])
    k_seeds = min(config.n_superpixels(H, W), xy.shape[0])
    row_d = jnp.transpose(disp_h, (1, 0, 2))  # (V, H, W): views (rc, c)
    col_d = jnp.transpose(disp_v, (1, 2, 0))  # (U, H, W): views (r, cc)
    cmp_lab, cmp_off = _ends(lab_row, lab_col)
    n_h = where[0][0].size
    shifts = SEED_SHIFTS[: config.seed_candidates] if config.centre_first else SEED_SHIFTS[:1]
    dense_centre = None if disparity is None else disparity[rc, cc]
    vis = (
        None if dense_centre is None or len(shifts) == 1 else _centre_visibility(dense_centre, U, V)
    )

    def candidate(shift):
        # one candidate partition per seed grid, with its completed centre view
        cluster, k = _kmeans(xy, F, H, W, k_seeds, config.kmeans_iters, shift)
        maps = []
        for (e, seg_i), seg, lbl, lab_map in zip(
            where, (seg_h, seg_v), (cluster[:n_h], cluster[n_h:]), (lab_h, lab_v), strict=True
        ):
            table = np.full(seg.valid.shape, -1, np.int32)
            table[e, seg_i] = lbl
            maps.append(_cluster_maps(jnp.asarray(table), lab_map))
        row_l = jnp.transpose(maps[0], (1, 0, 2))  # (V, H, W): views (rc, c)
        col_l = jnp.transpose(maps[1], (1, 2, 0))  # (U, H, W): views (r, cc)
        c_l = c_d = None
        if config.centre_first:
            c_l, c_d = _centre_labels(
                config, row_l, row_d, col_l, col_d, lab_row[cc], cmp_lab, cmp_off,
                dense_centre, lo, span, k,
            )  # fmt: skip
        return row_l, col_l, c_l, c_d, k

    def score(cand):
        c_l, c_d = cand[2], cand[3]
        view_vis = vis if vis is not None else _centre_visibility(c_d[0], U, V)
        return _predicted_self_similarity(c_l[0], view_vis)

    row_l, col_l, c_l, c_d, k = _most_consistent(shifts, candidate, score)
    seconds["cluster"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    if config.centre_first:
        if disparity is None:
            labels, disp, agree = _project_resolve(row_l, row_d, col_l, col_d, c_l[0], c_d[0])
        else:
            labels, agree = _project_dense(c_l[0], disparity, config.dense_tol)
            disp = disparity
            # The cross-hair segmentations then only serve the hole propagation below.
            row_d, col_d = disparity[rc], disparity[:, cc]
    else:
        labels, disp, agree = _project_agree(
            row_l, row_d, col_l, col_d, keep=config.keep_disagreeing
        )
    consistent = float(jnp.mean(agree))
    # Propagation on the cross-hair (eq 5.1), then into the other views, then nearest fill.
    cross_l = jnp.concatenate([labels[rc], labels[:, cc]])
    cross_d = jnp.concatenate([disp[rc], disp[:, cc]])
    cross_lab = jnp.concatenate([lab_row, lab_col])
    cross_l, cross_d = _propagate(
        config, cross_lab, cross_l, cross_d, jnp.asarray(_cross_offsets(U, V)), cmp_lab, cmp_off
    )
    labels, disp = _fill_from_cross(
        labels, disp, cross_l[:V], cross_d[:V], cross_l[V:], cross_d[V:]
    )
    labels = labels.at[rc].set(cross_l[:V]).at[:, cc].set(cross_l[V:])
    disp = disp.at[rc].set(cross_d[:V]).at[:, cc].set(cross_d[V:])
    fl, fd = nearest_fill(labels.reshape(U * V, H, W), disp.reshape(U * V, H, W))
    fl, fd = fl.reshape(U, V, H, W), fd.reshape(U, V, H, W)
    if disparity is not None and config.centre_first:
        fd = disparity
    fl, fd = jax.block_until_ready((fl, fd))
    seconds["label"] = time.perf_counter() - t0
    return SuperpixelResult(
        labels=fl,
        disparity=fd,
        n_superpixels=int(k),
        consistent_fraction=consistent,
        seconds=seconds,
    )


def kmeans_superpixels(
    lf: LightField,
    disparity: Float[ArrayLike, "H W"],
    config: SuperpixelConfig = SuperpixelConfig(),
) -> SuperpixelResult:
    """The k-means baseline of thesis Sec. 5.2.2: cluster centre-view pixels, project.

    Every centre-view pixel becomes ``(x, y, d, L*, a*, b*)`` with the same weights as
    `superpixels` (``d`` normalised over the scene's range); scikit-learn k-means from
    ``round(H W / size²)`` uniform seeds (with ``config.seed_candidates > 1``, from that many
    shifted seed grids, keeping the clustering with the lowest predicted self-similarity
    error under ``disparity``, as `superpixels` does; ``seed_candidates=1`` is the thesis'
    baseline); the labels are forward-projected into every view
    with ``disparity`` (z-buffer: nearer wins); the pixels no projection reaches take the
    label of the cheapest labelled pixel nearby in ``(x, y, L*, a*, b*)`` (eq 5.1 without the
    photo-consistency term), and the rest the nearest labelled pixel.

    Args:
        lf: the light field (at least 3x3 views).
        disparity: ``(H, W)`` centre-view disparity (ours or ground truth), pixels per view
            step.
        config: parameters (``size``, the feature weights, ``kmeans_iters``, the propagation
            settings).

    Returns:
        A `SuperpixelResult`; ``disparity`` holds the projected centre disparity.

    Raises:
        ValueError: on a disparity map that is not ``(H, W)`` or not finite, or bad views.

    References:
        Thesis Sec. 5.2.2 (k-means baseline).
    """
    _check_lf(lf)
    U, V = lf.grid
    H, W = lf.size
    d = np.asarray(disparity, np.float32)
    if d.shape != (H, W):
        raise ValueError(f"disparity must have shape {(H, W)}; got {d.shape}")
    if not np.isfinite(d).all():
        raise ValueError("disparity contains NaN or Inf")
    seconds: dict[str, float] = {}
    t0 = time.perf_counter()
    lab_views = rgb_to_lab(lf.views)
    lab_c = np.asarray(lab_views[U // 2, V // 2], np.float64).reshape(-1, 3)
    gy, gx = np.meshgrid(
        np.arange(H, dtype=np.float64), np.arange(W, dtype=np.float64), indexing="ij"
    )
    lo, span = _disparity_scale(lf, d.ravel())
    F = _features(gx.ravel(), gy.ravel(), d.ravel(), lab_c, lo, span, config)
    k_seeds = config.n_superpixels(H, W)
    xy = np.stack([gx.ravel(), gy.ravel()], -1)
    shifts = SEED_SHIFTS[: config.seed_candidates]
    vis = _centre_visibility(d, U, V) if len(shifts) > 1 else None
    centre, k = _most_consistent(
        shifts,
        lambda shift: _kmeans(xy, F, H, W, k_seeds, config.kmeans_iters, shift),
        lambda cand: _predicted_self_similarity(cand[0].reshape(H, W), vis),
    )
    centre = jnp.asarray(centre.reshape(H, W))
    seconds["cluster"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    offsets = jnp.asarray(_view_offsets(U, V))
    labels, disp = _project_centre(centre, jnp.asarray(d), offsets)
    consistent = float(jnp.mean(labels >= 0))
    zeros = jnp.zeros((1, H, W, 3), jnp.float32)
    labels, disp = _propagate(
        config,
        lab_views.reshape(U * V, H, W, 3),
        labels,
        disp,
        offsets,
        zeros,
        jnp.zeros((1, 2), jnp.float32),
        w_photo=jnp.float32(0.0),
    )
    labels, disp = nearest_fill(labels, disp)
    labels, disp = jax.block_until_ready((labels.reshape(U, V, H, W), disp.reshape(U, V, H, W)))
    seconds["label"] = time.perf_counter() - t0
    return SuperpixelResult(
        labels=labels,
        disparity=disp,
        n_superpixels=int(k),
        consistent_fraction=consistent,
        seconds=seconds,
    )


__all__ = ["EPISegments", "SuperpixelResult", "kmeans_superpixels", "superpixels"]
