"""Bad input raises with a message naming the problem; the input folder is never written."""

from __future__ import annotations

import numpy as np
import pytest

from mvedge_jax.io import (
    detect_layout,
    load_light_field,
    read_hci4d,
    read_hci_old,
    read_view_grid,
    write_pfm,
)

H, W = 16, 20


def test_missing_folder(tmp_path):
    with pytest.raises(FileNotFoundError, match="light field folder not found: .*nowhere"):
        load_light_field(tmp_path / "nowhere")


def test_path_is_a_file(tmp_path):
    f = tmp_path / "x.png"
    f.write_bytes(b"")
    with pytest.raises(NotADirectoryError, match="got a file"):
        load_light_field(f)


def test_empty_folder(tmp_path):
    with pytest.raises(ValueError, match="no recognised light-field layout .* empty folder"):
        load_light_field(tmp_path)


def test_unrecognised_folder_lists_contents(tmp_path, synth):
    synth.rgb(tmp_path / "photo.png", np.zeros((4, 4, 3), np.uint8))
    (tmp_path / "readme.txt").write_text("x")
    with pytest.raises(ValueError, match="no recognised light-field layout.*photo.png, readme.txt"):
        load_light_field(tmp_path)


def test_views_of_different_sizes(tmp_path, synth):
    v = synth.views(3, 3, H, W)
    folder = synth.grid(tmp_path / "g", v)
    synth.rgb(folder / "02_01.png", np.zeros((H, W + 2, 3), np.uint8))
    with pytest.raises(
        ValueError, match=r"different sizes.*01_01.png is 16x20 \(HxW\) but 02_01.png is 16x22"
    ):
        load_light_field(folder, transpose=False)


def test_missing_centre_view_hci(tmp_path, synth):
    folder = synth.hci4d(tmp_path / "s", synth.views(9, 9, H, W), skip=[(4, 4)])
    with pytest.raises(FileNotFoundError, match=r"centre view missing.*input_Cam040\.png"):
        read_hci4d(folder)


def test_missing_centre_view_grid(tmp_path, synth):
    folder = synth.grid(
        tmp_path / "g",
        synth.views(5, 5, H, W),
        lambda r, c: f"v_{r + 1:02d}_{c + 1:02d}.png",
        skip=[(2, 2)],
    )
    with pytest.raises(FileNotFoundError, match=r"centre view missing.*file indices 03_03"):
        load_light_field(folder)


@pytest.mark.parametrize("gap", [(4, 0), (8, 4), (4, 7)])
def test_gap_in_cross_hair(tmp_path, synth, gap):
    folder = synth.hci4d(tmp_path / "s", synth.views(9, 9, H, W), skip=[gap])
    k = 9 * gap[0] + gap[1]
    with pytest.raises(ValueError, match=rf"gap in the central cross-hair.*input_Cam{k:03d}\.png"):
        load_light_field(folder)


def test_gap_outside_crop_is_fine(tmp_path, synth):
    folder = synth.hci4d(tmp_path / "s", synth.views(9, 9, H, W), skip=[(4, 0)])
    lf = load_light_field(folder, views=(7, 7))
    assert lf.grid == (7, 7) and bool(lf.view_mask.all())


def test_gap_in_grid_labels(tmp_path, synth):
    """A missing file-row inside the cross-hair of a 1-based grid is reported by its label."""
    folder = synth.grid(
        tmp_path / "g",
        synth.views(5, 5, H, W),
        lambda r, c: f"view_{r + 1:02d}_{c + 1:02d}.png",
        skip=[(1, 2)],
    )
    with pytest.raises(ValueError, match=r"cross-hair.*file indices 02_03"):
        load_light_field(folder, transpose=False)


@pytest.mark.parametrize("grid", [(2, 3), (3, 2), (1, 5)])
def test_fewer_than_three_views(tmp_path, synth, grid):
    folder = synth.grid(tmp_path / "g", synth.views(*grid, H, W))
    with pytest.raises(ValueError, match=rf"{grid[0]}x{grid[1]} grid.*at least 3 views"):
        load_light_field(folder)


@pytest.mark.parametrize(
    "views, match",
    [
        ((11, 11), r"views=11x11 is larger than the 9x9 grid"),
        ((9, 10), r"views=9x10 is larger than the 9x9 grid"),
        ((2, 2), r"at least 3 views"),
        (0, r"at least 3 views"),
        ((3, 3, 3), r"an int or a pair"),
        ("7x7", r"an int or a pair"),
    ],
)
def test_bad_crop(tmp_path, synth, views, match):
    folder = synth.hci4d(tmp_path / "s", synth.views(9, 9, 16, 16))
    with pytest.raises(ValueError, match=match):
        load_light_field(folder, views=views)


@pytest.mark.parametrize("scale", [0, -0.5, 1.5, float("nan"), "half"])
def test_bad_scale(tmp_path, synth, scale):
    folder = synth.hci4d(tmp_path / "s", synth.views(3, 3, 16, 16))
    with pytest.raises(ValueError, match="scale"):
        load_light_field(folder, scale=scale)


def test_corrupt_png(tmp_path, synth):
    folder = synth.grid(tmp_path / "g", synth.views(3, 3, H, W))
    data = (folder / "00_01.png").read_bytes()
    (folder / "00_01.png").write_bytes(data[: len(data) // 3])
    with pytest.raises(ValueError, match=r"cannot decode image .*00_01\.png"):
        load_light_field(folder, transpose=False)


def test_truncated_gt_pfm(tmp_path, synth):
    folder = synth.hci4d(tmp_path / "s", synth.views(3, 3, H, W), gt=np.zeros((H, W), np.float32))
    p = folder / "gt_disp_lowres.pfm"
    p.write_bytes(p.read_bytes()[:-10])
    with pytest.raises(ValueError, match=r"truncated PFM .*gt_disp_lowres\.pfm"):
        load_light_field(folder)


def test_gt_wrong_size(tmp_path, synth):
    folder = synth.hci4d(
        tmp_path / "s", synth.views(3, 3, H, W), gt=np.zeros((H, W + 1), np.float32)
    )
    with pytest.raises(ValueError, match=r"ground truth .* is 16x21, the views are 16x20"):
        load_light_field(folder)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_gt(tmp_path, synth, bad):
    gt = np.zeros((H, W), np.float32)
    gt[3, 5] = bad
    folder = synth.hci4d(tmp_path / "s", synth.views(3, 3, H, W), gt=gt)
    with pytest.raises(ValueError, match=r"1 NaN/Inf values .*first at y=3, x=5"):
        load_light_field(folder)


def test_hci_old_truncated_depth(tmp_path, synth):
    folder = synth.hci_old(tmp_path / "o", synth.views(3, 3, H, W), np.ones((H, W), np.float32))
    p = folder / "depth.bin"
    p.write_bytes(p.read_bytes()[:-4])
    with pytest.raises(
        ValueError, match=rf"depth.bin has {4 * H * W - 4} bytes; expected {4 * H * W}"
    ):
        read_hci_old(folder)


def test_hci_old_zero_depth(tmp_path, synth):
    folder = synth.hci_old(tmp_path / "o", synth.views(3, 3, H, W), np.ones((H, W), np.float32))
    d = np.fromfile(folder / "depth.bin", "<f4")
    d[7] = 0.0
    d.tofile(folder / "depth.bin")
    with pytest.raises(ValueError, match="NaN/Inf"):
        read_hci_old(folder)
    # ... unless the mask marks that pixel invalid
    mask = np.ones((H, W), bool)
    mask.flat[7] = False
    synth.hci_old(tmp_path / "o2", synth.views(3, 3, H, W), np.ones((H, W), np.float32), mask=mask)
    d.tofile(tmp_path / "o2" / "depth.bin")
    lf = read_hci_old(tmp_path / "o2")
    assert not bool(lf.centre_gt_mask.reshape(-1)[7]) and float(lf.centre_gt.reshape(-1)[7]) == 0.0


def test_hci_old_attributes_contradict_files(tmp_path, synth):
    folder = synth.hci_old(tmp_path / "o", synth.views(3, 3, H, W), np.ones((H, W), np.float32))
    text = (folder / "attributes.dat").read_text().replace("3 //hRes", "5 //hRes")
    (folder / "attributes.dat").write_text(text)
    with pytest.raises(
        ValueError, match=r"declares 3x5 views \(vRes x hRes\) but .* holds a 3x3 grid"
    ):
        read_hci_old(folder)


def test_hci_old_attributes_wrong_resolution(tmp_path, synth):
    folder = synth.hci_old(tmp_path / "o", synth.views(3, 3, H, W), np.ones((H, W), np.float32))
    text = (folder / "attributes.dat").read_text().replace(f"{W} //xRes", f"{W * 2} //xRes")
    (folder / "attributes.dat").write_text(text)
    with pytest.raises(
        ValueError, match=r"attributes.dat .* gives 16x40 \(yRes x xRes\) but the views are 16x20"
    ):
        read_hci_old(folder)


def test_hci_old_malformed_attributes(tmp_path, synth):
    folder = synth.hci_old(tmp_path / "o", synth.views(3, 3, H, W), np.ones((H, W), np.float32))
    (folder / "attributes.dat").write_text("768 //xRes\nseven //yRes\n")
    with pytest.raises(ValueError, match=r"attributes.dat:2: expected 'number //name'"):
        read_hci_old(folder)


def test_malformed_parameters_cfg(tmp_path, synth):
    folder = synth.hci4d(tmp_path / "s", synth.views(3, 3, 16, 16))
    (folder / "parameters.cfg").write_text("[meta]\ndisp_min = low\ndisp_max = 1\n")
    with pytest.raises(ValueError, match=r"disp_min = 'low' is not a number"):
        load_light_field(folder)
    (folder / "parameters.cfg").write_text("no section header\n")
    with pytest.raises(ValueError, match="malformed HCI parameters file"):
        load_light_field(folder)


def test_ambiguous_grid_families(tmp_path, synth):
    v = synth.views(3, 3, 16, 16)
    synth.grid(tmp_path, v, lambda r, c: f"view_{r}_{c}.png")
    synth.grid(tmp_path, v, lambda r, c: f"disp_{r}_{c}.png")
    with pytest.raises(ValueError, match=r"ambiguous view grid.*disp_RR_CC.png.*view_RR_CC.png"):
        detect_layout(tmp_path)


def test_duplicate_view(tmp_path, synth):
    v = synth.views(3, 3, 16, 16)
    synth.grid(tmp_path, v, lambda r, c: f"a_{3 * r + c:03d}_{r}_{c}.png")
    synth.rgb(tmp_path / "a_100_1_1.png", v[1, 1])
    with pytest.raises(ValueError, match=r"two files for view 01_01"):
        detect_layout(tmp_path)


def test_hci_camera_index_outside_grid(tmp_path, synth):
    folder = synth.hci4d(tmp_path / "s", synth.views(3, 3, 16, 16))
    synth.rgb(folder / "input_Cam009.png", np.zeros((16, 16, 3), np.uint8))
    with pytest.raises(ValueError, match=r"camera index 009 does not fit the 3x3 grid"):
        load_light_field(folder)


def test_specific_readers_reject_other_layouts(tmp_path, synth):
    grid = synth.grid(tmp_path / "g", synth.views(3, 3, 16, 16))
    hci = synth.hci4d(tmp_path / "h", synth.views(3, 3, 16, 16))
    with pytest.raises(ValueError, match="not an HCI 4D folder"):
        read_hci4d(grid)
    with pytest.raises(ValueError, match="not an old HCI folder"):
        read_hci_old(grid)
    with pytest.raises(ValueError, match="not a generic view grid"):
        read_view_grid(hci)


def test_input_folder_is_never_written(tmp_path, synth):
    H, W = 32, 40  # scale 0.5 keeps the views above MIN_VIEW_SIZE
    gt = np.ones((H, W), np.float32)
    folders = [
        synth.hci4d(tmp_path / "h", synth.views(9, 9, H, W), gt=gt),
        synth.hci_old(tmp_path / "o", synth.views(3, 3, H, W), gt),
        synth.grid(tmp_path / "g", synth.views(5, 5, H, W), lambda r, c: f"x_{r}_{c}.png"),
    ]
    write_pfm(folders[0] / "gt_disp_lowres_Cam000.pfm", gt)
    before = synth.listing(tmp_path)
    for f in folders:
        load_light_field(f)
        load_light_field(f, views=3, scale=0.5)
    assert synth.listing(tmp_path) == before
