"""Layout detection and reading on small synthetic folders (exact values, orientation)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from mvedge_jax.io import (
    LayoutInfo,
    check_parallax_axes,
    depth_to_disparity,
    detect_layout,
    load_light_field,
    load_light_field_with_info,
    read_hci4d,
    read_hci_old,
    read_rgb,
    read_view_grid,
    read_views,
    write_pfm,
    write_png,
)
from mvedge_jax.lightfield import LightField

H, W = 48, 64


def _as_float(v: np.ndarray) -> np.ndarray:
    return v.astype(np.float32) / np.float32(255.0)


def _warp_error(lf: LightField, d: np.ndarray) -> float:
    """Mean |centre - view warped to the centre with disparity d| over the cross-hair."""
    views = np.asarray(lf.views)
    U, V, h, w = views.shape[:4]
    rc, cc = U // 2, V // 2
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    errs = []
    for r, c in [(rc, 0), (rc, V - 1), (0, cc), (U - 1, cc)]:
        dr, dc = r - rc, c - cc
        warped = cv2.remap(
            views[r, c], xx - dc * d, yy - dr * d, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
        )
        m = max(abs(dr), abs(dc)) * int(np.ceil(np.abs(d).max())) + 2
        errs.append(np.abs(warped - views[rc, cc])[m:-m, m:-m].mean())
    return float(np.mean(errs))


# ---- HCI 4D -------------------------------------------------------------------------------


def test_hci4d_full(tmp_path, synth):
    v = synth.views(9, 9, H, W, d=1)
    gt = np.full((H, W), 1.0, np.float32)
    gt[:10, :10] = 0.25
    folder = synth.hci4d(tmp_path / "scene", v, gt=gt, drange=(-1.5, 2.5))
    info = detect_layout(folder)
    assert info.layout == "hci4d" and info.grid == (9, 9) and len(info.files) == 81
    assert info.gt_files == {(4, 4): str(folder / "gt_disp_lowres.pfm")}
    lf = read_hci4d(folder)
    assert lf.views.shape == (9, 9, H, W, 3) and lf.views.dtype == np.float32
    np.testing.assert_array_equal(np.asarray(lf.views), _as_float(v))
    assert bool(lf.view_mask.all())
    assert lf.disparity_range == (-1.5, 2.5)
    assert lf.name == "scene" and lf.source == str(folder)
    np.testing.assert_array_equal(np.asarray(lf.centre_gt), gt)
    gm = np.asarray(lf.gt_mask)
    assert gm[4, 4].all()
    assert gm.reshape(81, -1).any(axis=1).sum() == 1  # GT for the centre view only
    # the synthetic scene is at disparity +1 under SPEC §0: warping with +1 beats -1 and 0
    e = {s: _warp_error(lf, np.full((H, W), s, np.float32)) for s in (1.0, -1.0, 0.0)}
    assert e[1.0] < 1e-6 < e[0.0] and e[1.0] < e[-1.0]


def test_hci4d_partial_star_grid_and_per_view_gt(tmp_path, synth):
    v = synth.views(9, 9, H, W)
    star = {(r, c) for r in range(9) for c in range(9) if r == 4 or c == 4 or r == c or r + c == 8}
    assert len(star) == 33
    skip = [(r, c) for r in range(9) for c in range(9) if (r, c) not in star]
    folder = synth.hci4d(tmp_path / "star", v, skip=skip)
    gt7 = np.random.default_rng(1).normal(size=(H, W)).astype(np.float32)
    write_pfm(folder / "gt_disp_lowres_Cam007.pfm", gt7)
    lf = load_light_field(folder)
    mask = np.asarray(lf.view_mask)
    assert mask.sum() == 33
    assert {tuple(p) for p in np.argwhere(mask)} == star
    assert not np.asarray(lf.views)[~mask].any()  # absent views are zero
    np.testing.assert_array_equal(np.asarray(lf.views)[mask], _as_float(v)[mask])
    np.testing.assert_array_equal(np.asarray(lf.gt_disparity)[0, 7], gt7)
    assert not np.asarray(lf.gt_mask)[4, 4].any()


def test_hci4d_without_parameters_cfg(tmp_path, synth):
    folder = synth.hci4d(tmp_path / "s", synth.views(9, 9, 16, 16))
    (folder / "parameters.cfg").unlink()
    lf, info = load_light_field_with_info(folder)
    assert lf.grid == (9, 9) and lf.disparity_range is None
    assert any("parameters.cfg" in n for n in info.notes)


def test_hci4d_non_square_grid_from_cfg(tmp_path, synth):
    v = synth.views(5, 7, 16, 20)
    folder = synth.hci4d(tmp_path / "s", v)  # k = 7*row + col, num_cams_x = 7
    lf = load_light_field(folder)
    assert lf.grid == (5, 7)
    np.testing.assert_array_equal(np.asarray(lf.views), _as_float(v))


# ---- generic view grids -------------------------------------------------------------------

NAMINGS = {
    "RR_CC 0-based": (lambda r, c: f"{r:02d}_{c:02d}.png", "RR_CC.png", 0, 0),
    "view_RR_CC 1-based": (
        lambda r, c: f"view_{r + 1:02d}_{c + 1:02d}.png",
        "view_RR_CC.png",
        1,
        1,
    ),
    "name_RR_CC numeric name": (
        lambda r, c: f"2067_{r + 1:02d}_{c + 1:02d}.png",
        "2067_RR_CC.png",
        1,
        1,
    ),
    "name_NNN_RR_CC serpentine": (
        lambda r, c: (
            f"IMG_0001_{5 * r + (c if r % 2 == 0 else 4 - c) + 1:03d}_{r + 1:02d}_{c + 1:02d}.png"
        ),
        "IMG_0001_NNN_RR_CC.png",
        1,
        1,
    ),
    "offset sub-grid": (lambda r, c: f"{r + 9:02d}_{c + 8:02d}.png", "RR_CC.png", 9, 8),
    "jpeg-free bmp": (lambda r, c: f"cam_{r}_{c}.bmp", "cam_RR_CC.bmp", 0, 0),
}


@pytest.mark.parametrize("naming", list(NAMINGS))
def test_view_grid_namings(tmp_path, synth, naming):
    name, pattern, r0, c0 = NAMINGS[naming]
    v = synth.views(5, 5, H, W, d=1)
    folder = synth.grid(tmp_path / "g", v, name)
    lf, info = load_light_field_with_info(folder)
    assert info.layout == "view_grid" and info.pattern == pattern
    assert info.row_labels == tuple(range(r0, r0 + 5)) and info.col_labels == tuple(
        range(c0, c0 + 5)
    )
    assert not info.transposed
    assert any("file indices are (row, col)" in n for n in info.notes)
    np.testing.assert_array_equal(np.asarray(lf.views), _as_float(v))
    assert lf.gt_disparity is None and lf.disparity_range is None


def test_view_grid_non_square_rows_are_rows(tmp_path, synth):
    v = synth.views(3, 7, H, W, d=1)
    lf = read_view_grid(synth.grid(tmp_path / "g", v))
    assert lf.grid == (3, 7)
    np.testing.assert_array_equal(np.asarray(lf.views), _as_float(v))


def test_view_grid_column_first_names_are_swapped(tmp_path, synth):
    """Files written as CC_RR (horizontal index first, as the Lytro-1 export does)."""
    v = synth.views(5, 5, H, W, d=1)
    folder = synth.grid(tmp_path / "g", v, lambda r, c: f"img_{c + 1:02d}_{r + 1:02d}.png")
    check = check_parallax_axes(detect_layout(folder))
    assert check.swap and check.decided
    lf, info = load_light_field_with_info(folder)
    assert info.transposed
    np.testing.assert_array_equal(np.asarray(lf.views), _as_float(v))
    forced = read_view_grid(folder, transpose=False)
    np.testing.assert_array_equal(np.asarray(forced.views), _as_float(v).transpose(1, 0, 2, 3, 4))


def test_view_grid_without_parallax_keeps_file_order(tmp_path, synth):
    v = synth.views(3, 3, H, W, d=0)
    lf, info = load_light_field_with_info(synth.grid(tmp_path / "g", v))
    assert not info.transposed and any("undecided" in n for n in info.notes)


def test_view_grid_ignores_other_files(tmp_path, synth):
    v = synth.views(3, 3, 16, 16)
    folder = synth.grid(tmp_path / "g", v)
    (folder / "notes.txt").write_text("hi")
    synth.rgb(folder / "thumbnail.png", v[0, 0])
    assert load_light_field(folder, transpose=False).grid == (3, 3)


# ---- old HCI ------------------------------------------------------------------------------


def test_hci_old_depth_to_disparity(tmp_path, synth):
    v = synth.views(3, 3, H, W, d=2)
    disp = np.full((H, W), 2.0, np.float32)
    disp[5:9, 7:30] = -3.25
    mask = np.ones((H, W), bool)
    mask[0, :5] = False
    folder = synth.hci_old(tmp_path / "old", v, disp, mask=mask)
    lf, info = load_light_field_with_info(folder)
    assert info.layout == "hci_old" and lf.grid == (3, 3) and lf.size == (H, W)
    assert info.depth_to_disparity == (614.4, 9.375, 288.0)
    assert lf.disparity_range == (-3.5, 4.5)
    gt = np.asarray(lf.centre_gt)
    np.testing.assert_allclose(gt[mask], disp[mask], atol=2e-3)  # float32 depth round trip
    np.testing.assert_array_equal(np.asarray(lf.centre_gt_mask), mask)
    assert (gt[~mask] == 0).all()
    assert _warp_error(lf, gt) < 0.1 * _warp_error(lf, -gt)
    # the lf/ sub-folder is accepted too
    assert read_hci_old(folder / "lf").source == str(folder)


def test_hci_old_focal_zero_means_disparity(tmp_path, synth):
    disp = np.linspace(-1, 1, H * W, dtype=np.float32).reshape(H, W)
    folder = synth.hci_old(tmp_path / "o", synth.views(3, 3, H, W), disp, focal_length=0.0)
    np.testing.assert_array_equal(np.asarray(load_light_field(folder).centre_gt), disp)


def test_depth_to_disparity_formula():
    depth = np.array([10.0, 20.0, 614.4 * 9.375 / 288.0])
    np.testing.assert_allclose(
        depth_to_disparity(depth, dH=614.4, focal_length=9.375, shift=288),
        [614.4 * 9.375 / 10 - 288, 614.4 * 9.375 / 20 - 288, 0.0],
        rtol=1e-6,
        atol=1e-4,
    )
    assert np.isinf(depth_to_disparity(np.array([0.0]), dH=1, focal_length=1, shift=0)[0])


# ---- images -------------------------------------------------------------------------------


def test_image_bit_depths_and_channels(tmp_path):
    rng = np.random.default_rng(0)
    rgb16 = rng.integers(0, 65536, size=(6, 5, 3), dtype=np.uint16)
    cv2.imwrite(str(tmp_path / "a.png"), cv2.cvtColor(rgb16, cv2.COLOR_RGB2BGR))
    np.testing.assert_allclose(read_rgb(tmp_path / "a.png"), rgb16 / 65535.0, atol=1e-7)
    grey = rng.integers(0, 256, size=(6, 5), dtype=np.uint8)
    cv2.imwrite(str(tmp_path / "g.png"), grey)
    np.testing.assert_allclose(
        read_rgb(tmp_path / "g.png"), np.repeat(grey[..., None] / 255.0, 3, 2), atol=1e-7
    )
    rgba = rng.integers(0, 256, size=(6, 5, 4), dtype=np.uint8)
    cv2.imwrite(str(tmp_path / "x.png"), cv2.cvtColor(rgba, cv2.COLOR_RGBA2BGRA))
    np.testing.assert_allclose(read_rgb(tmp_path / "x.png"), rgba[..., :3] / 255.0, atol=1e-7)


def test_read_views_threads_match_serial(tmp_path, synth):
    v = synth.views(3, 3, 20, 24)
    folder = synth.grid(tmp_path / "g", v)
    paths = sorted(str(p) for p in folder.glob("*.png"))
    a = read_views(paths, workers=1)
    b = read_views(paths, workers=4)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a, _as_float(v.reshape(9, 20, 24, 3)))


def test_write_png_round_trip(tmp_path):
    img = np.random.default_rng(0).random((7, 9, 3)).astype(np.float32)
    write_png(tmp_path / "x.png", img)
    np.testing.assert_allclose(read_rgb(tmp_path / "x.png"), img, atol=0.5 / 255 + 1e-6)
    u8 = (img * 255).astype(np.uint8)
    write_png(tmp_path / "y.png", u8)
    np.testing.assert_array_equal(np.round(read_rgb(tmp_path / "y.png") * 255).astype(np.uint8), u8)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        write_png(tmp_path / "no" / "x.png", u8)
    with pytest.raises(ValueError, match="NaN"):
        write_png(tmp_path / "z.png", np.full((2, 2), np.nan))


def test_layout_info_is_plain_data(tmp_path, synth):
    info = detect_layout(synth.grid(tmp_path / "g", synth.views(3, 3, 8, 8)))
    assert isinstance(info, LayoutInfo)
    assert info.centre == (1, 1) and info.grid == (3, 3)
    assert info.describe_position((1, 2)) == "(row, col) = (1, 2) [file indices 01_02]"
