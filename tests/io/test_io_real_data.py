"""Every folder of the shared data loads with the grid, size and ground truth of MANIFEST.md,
and the ground truth follows SPEC §0 (checked by warping views onto the centre view)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from mvedge_jax.io import load_light_field, load_light_field_with_info

# From data/MANIFEST.md (its "size" column is width×height; here (H, W)). GT ranges are the
# measured min/max of the centre-view GT (MANIFEST rounds them); `meta` is the disparity range
# of parameters.cfg / attributes.dat.
SCENES = {
    # folder: (layout, grid (U, V), size (H, W), views present, GT (min, max) | None, meta | None)
    "hci4d/stratified/backgammon": ("hci4d", (9, 9), (512, 512), 81, (-1.553, 0.529), (-1.7, 0.7)),
    "hci4d/additional/antinous": ("hci4d", (9, 9), (512, 512), 81, (-3.131, 2.689), (-3.3, 2.8)),
    "hci4d/training_partial/dino_star33": ("hci4d", (9, 9), (512, 512), 33, None, (-1.9, 1.9)),
    "hci_old/stillLife_lf_3x3": (
        "hci_old",
        (3, 3),
        (768, 768),
        9,
        (-10.827, 10.252),
        (-10.827057, 16.158417),
    ),
    "real/lytro/epinet_2067": ("view_grid", (9, 9), (383, 552), 81, None, None),
    "real/lytro/lytro1_IMG_0001": ("view_grid", (10, 10), (256, 256), 100, None, None),
    "real/lytro_illum_5x5/epfl_iso_chart_1": ("view_grid", (5, 5), (432, 624), 25, None, None),
    "real/lytro_illum_5x5/stanford_lytro_general_11": (
        "view_grid",
        (5, 5),
        (376, 540),
        25,
        None,
        None,
    ),
    "real/stanford_gantry_3x3/lego_knights": ("view_grid", (3, 3), (1024, 1024), 9, None, None),
}
# Grids whose file names put the horizontal (column) index first, found from the parallax.
TRANSPOSED = {"real/lytro/lytro1_IMG_0001"}
# Scenes without GT whose geometry fixes the sign: rows (fractions of H) of a NEAR region and
# a FAR region; SPEC §0 says the near one has the larger disparity.
NEAR_FAR = {
    "real/lytro/epinet_2067": ((1 / 3, 2 / 3), (0, 1 / 6)),  # the dinosaur vs the bushes
    "real/lytro_illum_5x5/stanford_lytro_general_11": ((5 / 6, 1), (0, 1 / 6)),  # table vs wall
    "real/stanford_gantry_3x3/lego_knights": ((5 / 6, 1), (0, 1 / 6)),  # floor vs back wall
}
LABELS = {  # (first row label, first col label) in the file names
    "hci_old/stillLife_lf_3x3": (0, 0),
    "real/lytro/epinet_2067": (1, 1),
    "real/lytro/lytro1_IMG_0001": (1, 1),
    "real/lytro_illum_5x5/epfl_iso_chart_1": (1, 1),
    "real/lytro_illum_5x5/stanford_lytro_general_11": (1, 1),
    "real/stanford_gantry_3x3/lego_knights": (9, 8),
}


def warp_errors(
    views: np.ndarray, d: np.ndarray, mask: np.ndarray | None = None
) -> dict[str, float]:
    """Median |centre - view warped to the centre| over the 4 cross-hair end views, for the
    disparity ``d``, its negative and zero. SPEC §0: centre(x, y) ≈ view(x - dc d, y - dr d)."""
    U, V, H, W = views.shape[:4]
    rc, cc = U // 2, V // 2
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    mask = np.ones((H, W), bool) if mask is None else mask
    out = {}
    for name, dd in (("gt", d), ("neg", -d), ("zero", np.zeros_like(d))):
        errs = []
        for r, c in [(rc, 0), (rc, V - 1), (0, cc), (U - 1, cc)]:
            dr, dc = r - rc, c - cc
            w = cv2.remap(
                views[r, c],
                xx - dc * dd,
                yy - dr * dd,
                cv2.INTER_LINEAR,
                borderMode=cv2.BORDER_REPLICATE,
            )
            errs.append(np.median(np.abs(w - views[rc, cc]).mean(-1)[mask]))
        out[name] = float(np.mean(errs))
    return out


def parallax_maps(views: np.ndarray, max_side: int = 320) -> tuple[np.ndarray, np.ndarray]:
    """Disparity (px per view step at a reduced size) measured by optical flow from the centre
    view to the views ±k steps along the centre row (``d_h``) and column (``d_v``), with the
    SPEC §0 sign: flow = -offset * d."""
    U, V = views.shape[:2]
    rc, cc = U // 2, V // 2
    s = min(1.0, max_side / max(views.shape[2:4]))

    def g(r, c):
        im = cv2.resize(views[r, c], None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
        return np.round(cv2.cvtColor(im, cv2.COLOR_RGB2GRAY) * 255).astype(np.uint8)

    def flow(a, b):
        return cv2.calcOpticalFlowFarneback(a, b, None, 0.5, 4, 15, 5, 5, 1.2, 0)

    k = min(2, rc, cc)
    c0 = g(rc, cc)
    d_h = -(flow(c0, g(rc, cc + k))[..., 0] - flow(c0, g(rc, cc - k))[..., 0]) / (2 * k)
    d_v = -(flow(c0, g(rc + k, cc))[..., 1] - flow(c0, g(rc - k, cc))[..., 1]) / (2 * k)
    return d_h, d_v


@pytest.mark.parametrize("folder", list(SCENES))
def test_folder_loads_as_in_manifest(data_dir, folder):
    layout, grid, size, n_views, gt_range, meta = SCENES[folder]
    lf, info = load_light_field_with_info(data_dir / folder)
    assert info.layout == layout
    assert lf.grid == grid and lf.size == size
    assert lf.views.shape == (*grid, *size, 3) and lf.views.dtype == np.float32
    assert int(lf.view_mask.sum()) == n_views
    v = np.asarray(lf.views)
    assert 0.0 <= v.min() and v.max() <= 1.0 and v[lf.centre_index].std() > 0.05
    assert info.transposed == (folder in TRANSPOSED)
    if folder in LABELS:
        r0, c0 = LABELS[folder]
        labels = (
            (info.col_labels, info.row_labels)
            if info.transposed
            else (info.row_labels, info.col_labels)
        )
        assert labels == (tuple(range(r0, r0 + grid[0])), tuple(range(c0, c0 + grid[1])))
    assert lf.disparity_range == (pytest.approx(meta) if meta else None)
    if layout == "view_grid":  # (scenes with GT are checked by warping below)
        # Rows and columns carry the same disparity (no swapped or mirrored axis) ...
        d_h, d_v = parallax_maps(v)
        assert abs(np.median(d_h) - np.median(d_v)) < 0.05 + 0.2 * np.abs(d_h).mean()
        if np.ptp(np.percentile(d_h, [5, 95])) > 0.3:  # not a flat scene (the ISO chart)
            assert np.corrcoef(d_h.ravel(), d_v.ravel())[0, 1] > 0.5
        # ... and, where the scene says which part is nearer, it has the larger disparity.
        if folder in NEAR_FAR:
            h = d_h.shape[0]
            (n0, n1), (f0, f1) = NEAR_FAR[folder]
            near = np.median((d_h + d_v)[int(n0 * h) : int(n1 * h)]) / 2
            far = np.median((d_h + d_v)[int(f0 * h) : int(f1 * h)]) / 2
            assert near > far + 0.1, (near, far)
    if gt_range is None:
        assert lf.gt_disparity is None
        return
    gtm = np.asarray(lf.gt_mask)
    assert gtm.reshape(grid[0] * grid[1], -1).any(axis=1).sum() == 1  # centre view only
    gt = np.asarray(lf.centre_gt)
    m = np.asarray(lf.centre_gt_mask)
    assert m.mean() == 1.0  # every pixel valid in these scenes (stillLife's mask.png is all 255)
    assert (float(gt.min()), float(gt.max())) == pytest.approx(gt_range, abs=2e-3)
    # SPEC §0 sign and orientation: warping with the GT explains the views, -GT / 0 do not.
    e = warp_errors(v, gt, m)
    assert e["gt"] < 0.5 * min(e["neg"], e["zero"]), e


def test_dino_star33_view_mask(data_dir):
    lf = load_light_field(data_dir / "hci4d/training_partial/dino_star33", views=(9, 9), scale=0.25)
    r, c = np.mgrid[0:9, 0:9]
    star = (r == 4) | (c == 4) | (r == c) | (r + c == 8)
    np.testing.assert_array_equal(np.asarray(lf.view_mask), star)
    assert not np.asarray(lf.views)[~star].any()


def test_still_life_matches_manifest_formula(data_dir):
    """MANIFEST: disparity = 614.4·9.375/depth − 288 (depth.bin, float32 LE, raster order);
    our loader derives the constants from attributes.dat."""
    folder = data_dir / "hci_old/stillLife_lf_3x3"
    depth = np.fromfile(folder / "depth.bin", "<f4").reshape(768, 768).astype(np.float64)
    expect = 614.4 * 9.375 / depth - 288
    lf = load_light_field(folder)
    np.testing.assert_allclose(np.asarray(lf.centre_gt), expect, atol=1e-4)


def test_crop_and_downscale_keep_gt_consistent(data_dir):
    """antinous, central 7×7 at half resolution: the halved GT still warps the views onto the
    centre view."""
    full_gt = load_light_field(data_dir / "hci4d/additional/antinous", views=3).centre_gt
    lf = load_light_field(data_dir / "hci4d/additional/antinous", views=(7, 7), scale=0.5)
    assert lf.views.shape == (7, 7, 256, 256, 3)
    assert lf.disparity_range == pytest.approx((-1.65, 1.4))
    gt = np.asarray(lf.centre_gt)
    expect = cv2.resize(np.asarray(full_gt), (256, 256), interpolation=cv2.INTER_AREA) * 0.5
    np.testing.assert_allclose(gt, expect, atol=1e-5)
    e = warp_errors(np.asarray(lf.views), gt)
    assert e["gt"] < 0.5 * min(e["neg"], e["zero"]), e


def test_lytro1_after_transpose_rows_move_vertically(data_dir):
    """After the automatic swap, moving along a row of views shifts the image horizontally."""
    lf, info = load_light_field_with_info(data_dir / "real/lytro/lytro1_IMG_0001", views=7)
    assert info.transposed and any("(col, row): swapped" in n for n in info.notes)
    v = np.asarray(lf.views)
    g = lambda r, c: cv2.cvtColor(v[r, c], cv2.COLOR_RGB2GRAY)  # noqa: E731
    (sx, sy), _ = cv2.phaseCorrelate(g(3, 3), g(3, 6))
    assert abs(sx) > 1.0 and abs(sy) < 0.3 * abs(sx)
    (sx, sy), _ = cv2.phaseCorrelate(g(3, 3), g(6, 3))
    assert abs(sy) > 1.0 and abs(sx) < 0.3 * abs(sy)
