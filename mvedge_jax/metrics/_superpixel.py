"""Light-field superpixel metrics (thesis Sec. 5.2.3).

Label arrays are integer superpixel IDs of any values (not necessarily contiguous); the same ID
in two views is the same superpixel. Light fields are ``(U, V, H, W)``; 2-D ``(H, W)`` maps are
accepted where a metric is per view. Computed with NumPy/SciPy on the host (counting metrics,
not part of any jitted path).
"""

from __future__ import annotations

import numpy as np
from jaxtyping import ArrayLike
from scipy import ndimage


def _compact(a: np.ndarray) -> tuple[np.ndarray, int]:
    u, inv = np.unique(a, return_inverse=True)
    return inv.reshape(a.shape), int(u.size)


def _pair(labels: ArrayLike, gt: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    lab, g = np.asarray(labels), np.asarray(gt)
    if lab.shape != g.shape:
        raise ValueError(f"labels and ground truth shapes differ: {lab.shape} vs {g.shape}")
    if lab.ndim < 2 or lab.size == 0:
        raise ValueError(f"label maps must be at least 2-D and non-empty; got shape {lab.shape}")
    for name, a in (("labels", lab), ("ground truth", g)):
        if not np.issubdtype(a.dtype, np.integer):
            raise ValueError(f"{name} must be an integer label array; got dtype {a.dtype}")
    return lab, g


def _contingency(labels: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """``(n_superpixels, n_segments)`` overlap counts."""
    sp, n_sp = _compact(labels.ravel())
    g, n_g = _compact(gt.ravel())
    return np.bincount(sp * n_g + g, minlength=n_sp * n_g).reshape(n_sp, n_g)


def achievable_segmentation_accuracy(labels: ArrayLike, gt_ids: ArrayLike) -> float:
    """Achievable segmentation accuracy (ASA) of a superpixel segmentation.

    Every superpixel is given the ground-truth object that it overlaps most (over all views
    together); ASA is the fraction of pixels whose object is then right:
    ``Σ_P max_S |P ∩ S| / N``.

    Args:
        labels: ``(..., H, W)`` int superpixel labels (e.g. ``(U, V, H, W)``).
        gt_ids: int object IDs of the same shape.

    Returns:
        ASA in [0, 1] (1 = no superpixel straddles an object boundary).

    Raises:
        ValueError: on differing shapes, non-integer or empty inputs.

    References:
        Thesis Sec. 5.2.3; Liu et al., "Entropy rate superpixel segmentation", CVPR 2011.
    """
    lab, g = _pair(labels, gt_ids)
    c = _contingency(lab, g)
    return float(c.max(axis=1).sum() / lab.size)


def undersegmentation_error(labels: ArrayLike, gt_ids: ArrayLike) -> float:
    """Undersegmentation error in the formulation of thesis eq 5.3 (after Neubert & Protzel).

    ``UE = 1/N_S Σ_S [Σ_{P: P∩S≠∅} min(|P_in|, |P_out|)] / |S|`` with ``P_in = P ∩ S``,
    ``P_out = P \\ S``, the sum over the ``N_S`` ground-truth segments, all views pooled
    (a superpixel is the set of its pixels in every view). A superpixel that overlaps a
    segment only slightly adds only that small overlap (no penalty for large superpixels that
    just touch a segment).

    Args:
        labels: ``(..., H, W)`` int superpixel labels.
        gt_ids: int object IDs of the same shape.

    Returns:
        UE >= 0 (0 = every superpixel inside one object).

    Raises:
        ValueError: on differing shapes, non-integer or empty inputs.

    References:
        Thesis eq 5.3; Neubert & Protzel, "Superpixel benchmark and comparison", 2012.
    """
    lab, g = _pair(labels, gt_ids)
    c = _contingency(lab, g).astype(np.float64)
    size_p = c.sum(axis=1, keepdims=True)
    err = np.minimum(c, size_p - c)  # zero where P ∩ S = ∅
    return float(np.mean(err.sum(axis=0) / c.sum(axis=0)))


def boundary_mask(labels: ArrayLike) -> np.ndarray:
    """Pixels with a 4-neighbour of a different label (both sides of every boundary).

    Args:
        labels: ``(..., H, W)`` int labels; the last two axes are the image.

    Returns:
        bool array of the same shape.
    """
    a = np.asarray(labels)
    b = np.zeros(a.shape, bool)
    dx = a[..., :, 1:] != a[..., :, :-1]
    dy = a[..., 1:, :] != a[..., :-1, :]
    b[..., :, 1:] |= dx
    b[..., :, :-1] |= dx
    b[..., 1:, :] |= dy
    b[..., :-1, :] |= dy
    return b


def boundary_recall(labels: ArrayLike, gt_ids: ArrayLike, distance: int = 2) -> float:
    """Boundary recall: fraction of ground-truth boundary pixels near a superpixel boundary.

    Per view, a ground-truth boundary pixel (`boundary_mask` of ``gt_ids``) is a true positive
    when a superpixel boundary pixel lies within chessboard distance ``distance``; ``R = TP /
    (TP + FN)`` pooled over all views (eq 5.2).

    Args:
        labels: ``(..., H, W)`` int superpixel labels.
        gt_ids: int object IDs of the same shape.
        distance: chessboard tolerance in pixels (thesis 2).

    Returns:
        Recall in [0, 1]; 1 when the ground truth has no boundary.

    Raises:
        ValueError: on differing shapes, non-integer inputs or a negative distance.

    References:
        Thesis eq 5.2; Neubert & Protzel 2012.
    """
    lab, g = _pair(labels, gt_ids)
    if distance < 0:
        raise ValueError(f"distance must be >= 0; got {distance}")
    gb = boundary_mask(g)
    sb = boundary_mask(lab)
    size = (1,) * (lab.ndim - 2) + (2 * distance + 1, 2 * distance + 1)
    near = ndimage.maximum_filter(sb, size=size, mode="constant", cval=False)
    n = int(gb.sum())
    return 1.0 if n == 0 else float((gb & near).sum() / n)


def compactness(labels: ArrayLike) -> float:
    """Compactness of Schick et al. (thesis eq 5.4), mean over views.

    Per view ``C = Σ_S Q_S |S| / |I|`` with the isoperimetric quotient
    ``Q_S = 4π A_S / L_S²``; ``A_S`` is the superpixel's pixel count in that view and ``L_S``
    its perimeter, the number of unit pixel edges between it and another label or the image
    border. A ``k × k`` square alone in the image has ``Q = π / 4``.

    Args:
        labels: ``(H, W)`` or ``(..., H, W)`` int superpixel labels.

    Returns:
        Compactness in (0, 1].

    Raises:
        ValueError: on non-integer or empty input, or fewer than 2 dimensions.

    References:
        Thesis eq 5.4; Schick et al., "Measuring and evaluating the compactness of
        superpixels", ICPR 2012.
    """
    lab = np.asarray(labels)
    _pair(lab, lab)
    views = lab.reshape(-1, *lab.shape[-2:])
    out = []
    for v in views:
        sp, n = _compact(v)
        area = np.bincount(sp.ravel(), minlength=n).astype(np.float64)
        per = np.zeros(n)
        dx = sp[:, 1:] != sp[:, :-1]
        dy = sp[1:, :] != sp[:-1, :]
        for a, m in ((sp[:, 1:], dx), (sp[:, :-1], dx), (sp[1:, :], dy), (sp[:-1, :], dy)):
            per += np.bincount(a[m], minlength=n)
        for edge in (sp[0], sp[-1], sp[:, 0], sp[:, -1]):
            per += np.bincount(edge, minlength=n)
        q = 4.0 * np.pi * area / per**2
        out.append(float((q * area).sum() / v.size))
    return float(np.mean(out))


def _check_lf(labels: ArrayLike, disparity: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    lab = np.asarray(labels)
    d = np.asarray(disparity, np.float64)
    if lab.ndim != 4:
        raise ValueError(f"labels must have shape (U, V, H, W); got {lab.shape}")
    if d.shape != lab.shape:
        raise ValueError(f"disparity must have the labels' shape {lab.shape}; got {d.shape}")
    if not np.issubdtype(lab.dtype, np.integer):
        raise ValueError(f"labels must be integers; got dtype {lab.dtype}")
    return lab, d


def self_similarity_error(labels: ArrayLike, gt_disparity: ArrayLike) -> float:
    """Self-similarity error: how far a superpixel's centre moves when projected to the centre.

    In every view ``(r, c)`` each superpixel's pixels are projected into the centre view with
    the ground-truth disparity (``(x + dc d, y + dr d)``, SPEC §0) and their centroid taken;
    the error of a superpixel is the mean distance of its per-view centroids from their mean;
    the result is the mean over superpixels (pixels with NaN disparity are ignored).

    Args:
        labels: ``(U, V, H, W)`` int superpixel labels.
        gt_disparity: ``(U, V, H, W)`` float ground-truth disparity of every view (pixels per
            view step); NaN where unknown.

    Returns:
        Mean centroid deviation in pixels (0 = perfectly view-consistent).

    Raises:
        ValueError: on wrong shapes or non-integer labels, or no finite disparity.

    References:
        Thesis Sec. 5.2.3; Zhu et al., "4D light field superpixel and segmentation", CVPR 2017.
    """
    lab, d = _check_lf(labels, gt_disparity)
    ok = np.isfinite(d)
    if not ok.any():
        raise ValueError("gt_disparity has no finite value")
    sp, n = _compact(lab)
    px, py = _centre_coordinates(d)
    dev, nv = _centroid_deviation(sp, n, px, py, ok)
    keep = nv > 0
    return float(np.mean(dev[keep] / nv[keep]))


def _centre_coordinates(gt_disparity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(px, py)`` ``(U, V, H, W)``: every pixel of every view moved into the centre view
    with its disparity (``(x + dc d, y + dr d)``; 0 where the disparity is not finite)."""
    U, V, H, W = gt_disparity.shape
    dr = (np.arange(U) - U // 2)[:, None, None, None]
    dc = (np.arange(V) - V // 2)[None, :, None, None]
    y, x = np.meshgrid(np.arange(H), np.arange(W), indexing="ij")
    dz = np.where(np.isfinite(gt_disparity), gt_disparity, 0.0)
    return x + dc * dz, y + dr * dz


def _centroid_deviation(
    sp: np.ndarray, n: int, px: np.ndarray, py: np.ndarray, mask: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Per superpixel of the compact labels ``sp (U, V, H, W)`` in ``[0, n)``, over the
    ``mask`` pixels with centre-view coordinates ``px, py``: ``(sum of the distances of its
    per-view centroids from their mean (n,), number of views it appears in (n,))``."""
    U, V = sp.shape[:2]
    view = np.broadcast_to(np.arange(U * V).reshape(U, V, 1, 1), sp.shape)[mask]
    key = sp[mask] * (U * V) + view
    cnt = np.bincount(key, minlength=n * U * V).reshape(n, U * V)
    cx = np.bincount(key, px[mask], minlength=n * U * V).reshape(n, U * V)
    cy = np.bincount(key, py[mask], minlength=n * U * V).reshape(n, U * V)
    return centroid_deviation_from_sums(cnt, cx, cy)


def centroid_deviation_from_sums(
    cnt: np.ndarray, cx: np.ndarray, cy: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The self-similarity error's per-superpixel terms from per-view sums.

    `self_similarity_error` is ``mean(dev / views)`` over the superpixels with ``views > 0``.

    Args:
        cnt: ``(n, K)`` float pixel counts of ``n`` superpixels in ``K`` views.
        cx, cy: ``(n, K)`` float sums of those pixels' centre-view coordinates (pixels).

    Returns:
        ``dev (n,)``: per superpixel, the sum over the views it appears in (count > 0) of the
        distance of its centroid there from the mean of those centroids (pixels);
        ``views (n,)`` int: the number of such views.

    References:
        Thesis Sec. 5.2.3 (self-similarity error).
    """
    has = cnt > 0
    cx = np.where(has, cx / np.maximum(cnt, 1), 0.0)
    cy = np.where(has, cy / np.maximum(cnt, 1), 0.0)
    nv = has.sum(1)
    mx = cx.sum(1) / np.maximum(nv, 1)
    my = cy.sum(1) / np.maximum(nv, 1)
    dev = np.hypot(cx - mx[:, None], cy - my[:, None]) * has
    return dev.sum(1), nv


def labels_per_pixel(
    labels: ArrayLike,
    centre_disparity: ArrayLike,
    view_disparity: ArrayLike | None = None,
    *,
    tolerance: float = 0.1,
) -> float:
    """Mean number of distinct labels a centre-view point receives across the views.

    Each centre-view pixel with ground-truth disparity ``d`` is followed into every view
    (``(round(x - dc d), round(y - dr d))``); a view counts when the point lies inside it and is
    visible there: the view's disparity at that pixel is within ``tolerance`` of ``d``
    (``view_disparity``; without it the centre map forward-projected with a z-buffer decides,
    so points occluded in the centre view are never counted, as in the thesis). The result is
    the mean over centre pixels of the number of distinct labels (1 = perfectly consistent).

    Args:
        labels: ``(U, V, H, W)`` int superpixel labels.
        centre_disparity: ``(H, W)`` ground-truth disparity of the centre view.
        view_disparity: optional ``(U, V, H, W)`` ground truth of every view (NaN = unknown).
        tolerance: visibility tolerance, pixels per view step.

    Returns:
        Mean labels per pixel, >= 1.

    Raises:
        ValueError: on wrong shapes, non-integer labels or a non-finite centre disparity.

    References:
        Thesis Sec. 5.2.3 ("Number of labels per view-dependent pixel").
    """
    lab = np.asarray(labels)
    dc_map = np.asarray(centre_disparity, np.float64)
    if lab.ndim != 4:
        raise ValueError(f"labels must have shape (U, V, H, W); got {lab.shape}")
    U, V, H, W = lab.shape
    if dc_map.shape != (H, W):
        raise ValueError(f"centre_disparity must have shape {(H, W)}; got {dc_map.shape}")
    if not np.isfinite(dc_map).all():
        raise ValueError("centre_disparity contains NaN or Inf")
    if not np.issubdtype(lab.dtype, np.integer):
        raise ValueError(f"labels must be integers; got dtype {lab.dtype}")
    if view_disparity is not None:
        vd = np.asarray(view_disparity, np.float64)
        if vd.shape != lab.shape:
            raise ValueError(f"view_disparity must have shape {lab.shape}; got {vd.shape}")
    y, x = np.meshgrid(np.arange(H), np.arange(W), indexing="ij")
    rc, cc = U // 2, V // 2
    centre_lab = lab[rc, cc]
    seen = [centre_lab.ravel()]
    for r in range(U):
        for c in range(V):
            if (r, c) == (rc, cc):
                continue
            xt = np.rint(x - (c - cc) * dc_map).astype(np.int64)
            yt = np.rint(y - (r - rc) * dc_map).astype(np.int64)
            inside = (xt >= 0) & (xt < W) & (yt >= 0) & (yt < H)
            xt, yt = np.clip(xt, 0, W - 1), np.clip(yt, 0, H - 1)
            if view_disparity is not None:
                other = vd[r, c][yt, xt]
            else:  # z-buffer of the centre map projected into this view
                z = np.full(H * W, -np.inf)
                np.maximum.at(z, (yt * W + xt)[inside], dc_map[inside])
                other = z.reshape(H, W)[yt, xt]
            vis = inside & (np.abs(other - dc_map) <= tolerance)
            seen.append(np.where(vis, lab[r, c][yt, xt], centre_lab).ravel())
    s = np.sort(np.stack(seen, axis=0), axis=0)
    distinct = 1 + (s[1:] != s[:-1]).sum(axis=0)
    return float(distinct.mean())


def superpixel_metrics(
    labels: ArrayLike,
    *,
    gt_ids: ArrayLike | None = None,
    gt_disparity: ArrayLike | None = None,
    gt_mask: ArrayLike | None = None,
) -> dict[str, float]:
    """Every superpixel metric the available ground truth allows.

    Args:
        labels: ``(U, V, H, W)`` int superpixel labels.
        gt_ids: optional ``(U, V, H, W)`` object IDs: ASA, boundary recall, UE.
        gt_disparity: optional ``(U, V, H, W)`` disparity ground truth: self-similarity error
            and labels per pixel (from the centre view; views whose ``gt_mask`` is empty get
            the centre map forward-projected, with holes ignored).
        gt_mask: optional ``(U, V, H, W)`` bool, where ``gt_disparity`` is valid.

    Returns:
        ``{"compactness", ["asa", "boundary_recall", "undersegmentation_error"],
        ["self_similarity_error", "labels_per_pixel"]}``.

    Raises:
        ValueError: on inconsistent shapes.
    """
    lab = np.asarray(labels)
    out = {"compactness": compactness(lab)}
    if gt_ids is not None:
        out["asa"] = achievable_segmentation_accuracy(lab, gt_ids)
        out["boundary_recall"] = boundary_recall(lab, gt_ids)
        out["undersegmentation_error"] = undersegmentation_error(lab, gt_ids)
    if gt_disparity is not None:
        d = np.asarray(gt_disparity, np.float64)
        if d.shape != lab.shape:
            raise ValueError(f"gt_disparity must have shape {lab.shape}; got {d.shape}")
        U, V = lab.shape[:2]
        mask = np.ones(d.shape, bool) if gt_mask is None else np.asarray(gt_mask, bool)
        centre = d[U // 2, V // 2]
        full = bool(mask.all())
        if not full:
            d = _project_centre_gt(centre, U, V)
        out["self_similarity_error"] = self_similarity_error(lab, d)
        out["labels_per_pixel"] = labels_per_pixel(lab, centre, d if full else None)
    return out


def _project_centre_gt(centre: np.ndarray, U: int, V: int) -> np.ndarray:
    """Per-view disparity from the centre map (z-buffered forward projection, NaN holes)."""
    import jax.numpy as jnp

    from ..lightfield import forward_project

    out = np.full((U, V) + centre.shape, np.nan)
    for r in range(U):
        for c in range(V):
            p, ok = forward_project(
                jnp.asarray(centre, jnp.float32),
                jnp.asarray([r - U // 2, c - V // 2], jnp.float32),
            )
            out[r, c] = np.where(np.asarray(ok), np.asarray(p), np.nan)
    return out
