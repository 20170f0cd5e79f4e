"""HCI 4D benchmark protocol: border frame, the toolkit's Q25, region masks, bumpiness."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from mvedge_jax.metrics import (
    HCI_BORDER,
    benchmark_metrics,
    border_mask,
    bumpiness_x100,
    depth_metrics,
    q25_hci_x100,
    q25_x100,
    read_region_masks,
)

# |errors| = 0, .02, .05, .5, 1, .3 (as in test_metrics_depth.py)
D = np.array([[0.0, 0.02, 0.05], [0.5, -1.0, 0.0]], np.float32)
GT = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.3]], np.float32)


def _framed(inner_err: np.ndarray, border: int = HCI_BORDER, border_err: float = 10.0):
    """A map whose interior (inside the frame) has the errors ``inner_err`` and whose frame
    has error ``border_err``; returns ``(d, gt)``."""
    h, w = inner_err.shape
    d = np.full((h + 2 * border, w + 2 * border), border_err, np.float32)
    d[border : border + h, border : border + w] = inner_err
    return d, np.zeros_like(d)


def test_border_mask_counts():
    m = border_mask((40, 50))
    assert m.shape == (40, 50) and m.dtype == bool
    assert m.sum() == (40 - 30) * (50 - 30)
    assert not m[14].any() and m[15, 15] and not m[15, 14] and not m[:, -15:].any()
    assert border_mask((4, 4), 0).all()


def test_q25_hci_is_the_order_statistic_without_interpolation():
    # sorted 100·|err| = 0, 2, 5, 30, 50, 100; index int(0.25 · 6) = 1 → 2
    assert float(q25_hci_x100(D, GT)) == pytest.approx(2.0)
    # the interpolated quantile differs: position 1.25 → 2.75
    assert float(q25_x100(D, GT)) == pytest.approx(2.75, rel=1e-4)
    # n = 8: index 2
    d8 = np.array([0.07, 0.01, 0.03, 0.02, 0.9, 0.5, 0.04, 0.06], np.float32)
    assert float(q25_hci_x100(d8, np.zeros(8, np.float32))) == pytest.approx(3.0, rel=1e-5)
    mask = np.array([[False, True, True], [True, True, True]])  # errors .02 .05 .5 1 .3
    assert float(q25_hci_x100(D, GT, mask)) == pytest.approx(5.0, rel=1e-5)  # index 1
    assert np.isnan(float(q25_hci_x100(D, GT, np.zeros_like(mask))))


def test_benchmark_metrics_exclude_the_frame():
    inner = np.array([[0.0, 0.1], [0.05, -0.2]], np.float32)
    d, gt = _framed(inner)
    out = benchmark_metrics(d, gt)
    assert out["mse_x100"] == pytest.approx(100 * (0.01 + 0.0025 + 0.04) / 4, rel=1e-5)
    assert out["badpix_0.07"] == pytest.approx(50.0)
    assert out["badpix_0.01"] == pytest.approx(75.0)
    assert out["q25_x100"] == pytest.approx(5.0, rel=1e-5)  # sorted 0 5 10 20, index 1
    full = depth_metrics(d, gt)
    assert full["mse_x100"] > 1000  # the frame's error 10 counts in the full-frame protocol
    assert depth_metrics(d, gt, protocol="hci") == out
    # a smaller frame lets the border error in
    assert benchmark_metrics(d, gt, border=14)["badpix_0.7"] > 50


def test_benchmark_metrics_mask_nan_and_regions():
    inner = np.array([[0.0, 0.1], [0.05, -0.2]], np.float32)
    d, gt = _framed(inner)
    gt_mask = np.ones(d.shape, bool)
    gt_mask[16, 16] = False  # drops the -0.2 error
    out = benchmark_metrics(d, gt, gt_mask)
    assert out["mse_x100"] == pytest.approx(100 * (0.01 + 0.0025) / 3, rel=1e-5)
    d_nan = d.copy()
    d_nan[16, 16] = np.nan  # an invalid estimate is left out like an invalid GT
    assert benchmark_metrics(d_nan, gt)["mse_x100"] == pytest.approx(out["mse_x100"])
    region = np.zeros(d.shape, bool)
    region[15, 15:17] = True  # errors 0 and 0.1
    region[0, 0] = True  # outside the frame: ignored
    out = benchmark_metrics(d, gt, regions={"discontinuities": region, "planes": region})
    assert out["discontinuities_badpix_0.07"] == pytest.approx(50.0)
    assert out["discontinuities_mse_x100"] == pytest.approx(0.5, rel=1e-5)
    assert "planes_bumpiness_x100" in out and "discontinuities_bumpiness_x100" not in out


def test_bumpiness_hand_computed():
    H = W = 48
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    gt = np.zeros((H, W))
    inner = border_mask((H, W), 5)
    # linear error: zero Hessian
    assert float(bumpiness_x100(0.3 + 0.01 * x - 0.02 * y, gt, inner)) == pytest.approx(0, abs=1e-5)
    # e = a x²: the /16 Scharr derivative of x is 2, so d²/dx² → 2 · 2 · 2a = 8a
    a = 0.001
    assert float(bumpiness_x100(a * x**2, gt, inner)) == pytest.approx(100 * 8 * a, rel=1e-4)
    # clipped at 0.05
    assert float(bumpiness_x100(0.01 * x**2, gt, inner)) == pytest.approx(5.0, rel=1e-5)
    # mixed term: e = a x y → dxy = dyx = 4a, norm sqrt(2) · 4a
    got = float(bumpiness_x100(a * x * y, gt, inner))
    assert got == pytest.approx(100 * np.sqrt(2) * 4 * a, rel=1e-4)


def test_read_region_masks(tmp_path):
    m = np.zeros((8, 6), np.uint8)
    m[2:5, 1:3] = 255
    cv2.imwrite(str(tmp_path / "mask_planes_lowres.png"), m)
    rgb = np.zeros((8, 6, 3), np.uint8)
    rgb[0, 0] = (0, 0, 7)
    cv2.imwrite(str(tmp_path / "mask_discontinuities_lowres.png"), rgb)
    out = read_region_masks(tmp_path)
    assert sorted(out) == ["discontinuities", "planes"]
    assert out["planes"].dtype == bool and out["planes"].sum() == 6 and out["planes"][3, 2]
    assert out["discontinuities"].sum() == 1 and out["discontinuities"][0, 0]
    assert read_region_masks(tmp_path, ("smooth_surfaces",)) == {}
    with pytest.raises(FileNotFoundError, match="scene folder"):
        read_region_masks(tmp_path / "missing")


def test_bad_input():
    d, gt = _framed(np.zeros((2, 2), np.float32))
    with pytest.raises(ValueError, match="protocol"):
        depth_metrics(d, gt, protocol="kitti")
    with pytest.raises(ValueError, match="regions"):
        depth_metrics(d, gt, regions={"planes": np.ones(d.shape, bool)})
    with pytest.raises(ValueError, match="border"):
        benchmark_metrics(d, gt, border=16)
    with pytest.raises(ValueError, match="border"):
        border_mask((10, 10), -1)
    with pytest.raises(ValueError, match=r"region mask 'planes'.*\(32, 32\)"):
        benchmark_metrics(d, gt, regions={"planes": np.ones((3, 3), bool)})
    with pytest.raises(ValueError, match=r"\(H, W\)"):
        benchmark_metrics(np.zeros((2, 40, 40)), np.zeros((2, 40, 40)))
    with pytest.raises(ValueError, match="shapes differ"):
        benchmark_metrics(d, gt[:-1])
    with pytest.raises(ValueError, match="bumpiness"):
        bumpiness_x100(np.zeros(5), np.zeros(5))
