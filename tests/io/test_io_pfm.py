"""PFM read/write: round trips, byte order, bottom-to-top row order, corrupt files."""

from __future__ import annotations

import numpy as np
import pytest

from mvedge_jax.io import read_pfm, write_pfm


@pytest.mark.parametrize("little_endian", [True, False])
@pytest.mark.parametrize("shape", [(5, 7), (4, 6, 3)])
def test_round_trip(tmp_path, little_endian, shape):
    rng = np.random.default_rng(0)
    img = rng.normal(size=shape).astype(np.float32) * 100
    img.flat[0] = -0.0
    img.flat[1] = 3.4e38
    p = tmp_path / "x.pfm"
    write_pfm(p, img, little_endian=little_endian)
    raw = p.read_bytes()
    assert raw.startswith(b"Pf\n" if len(shape) == 2 else b"PF\n")
    assert (b"\n-1.0\n" in raw) == little_endian
    out = read_pfm(p)
    assert out.dtype == np.float32 and out.shape == shape
    np.testing.assert_array_equal(out, img)


def test_hand_written_greyscale_bottom_to_top_little_endian(tmp_path):
    # 2 wide, 3 high. Stored rows: first the BOTTOM image row [1, 2], then [3, 4], then the
    # TOP row [5, 6]; negative scale = little endian.
    data = np.array([1, 2, 3, 4, 5, 6], "<f4").tobytes()
    p = tmp_path / "hand.pfm"
    p.write_bytes(b"Pf\n2 3\n-1.0\n" + data)
    out = read_pfm(p)
    np.testing.assert_array_equal(out, [[5, 6], [3, 4], [1, 2]])
    # and write_pfm produces exactly these bytes
    q = tmp_path / "mine.pfm"
    write_pfm(q, out, little_endian=True)
    assert q.read_bytes() == p.read_bytes()


def test_hand_written_colour_big_endian(tmp_path):
    # 1 wide, 2 high, RGB; positive scale = big endian. Bottom pixel first.
    data = np.array([1, 2, 3, 10, 20, 30], ">f4").tobytes()
    p = tmp_path / "hand.pfm"
    p.write_bytes(b"PF\n1 2\n1.0\n" + data)
    out = read_pfm(p)
    assert out.shape == (2, 1, 3)
    np.testing.assert_array_equal(out[0, 0], [10, 20, 30])  # top row = stored last
    np.testing.assert_array_equal(out[1, 0], [1, 2, 3])
    q = tmp_path / "mine.pfm"
    write_pfm(q, out, little_endian=False)
    assert q.read_bytes() == p.read_bytes()


def test_header_on_one_line_and_scale_magnitude(tmp_path):
    data = np.array([7, 8], "<f4").tobytes()
    p = tmp_path / "x.pfm"
    p.write_bytes(b"Pf 2 1 -0.5\n" + data)
    np.testing.assert_array_equal(read_pfm(p), [[7, 8]])


def test_real_hci_gt_orientation(data_dir):
    """The HCI GT read top-to-bottom: backgammon's board (top of the image) is farther than
    the front edge at the bottom, i.e. disparity grows towards the bottom rows."""
    d = read_pfm(data_dir / "hci4d/stratified/backgammon/gt_disp_lowres.pfm")
    assert d.shape == (512, 512)
    assert np.median(d[-64:]) > np.median(d[:64]) + 0.3


@pytest.mark.parametrize(
    "content, match",
    [
        (b"", "corrupt PFM header"),
        (b"Pf\n2 3\n", "corrupt PFM header"),
        (b"P6\n2 3\n-1.0\n" + bytes(24), "not a PFM"),
        (b"Pf\ntwo 3\n-1.0\n" + bytes(24), "corrupt PFM header"),
        (b"Pf\n2 3\n0\n" + bytes(24), "scale 0"),
        (b"Pf\n-2 3\n-1.0\n" + bytes(24), "size"),
        (b"Pf\n2 3\n-1.0\n" + bytes(23), "truncated PFM .* expected 24 bytes"),
        (b"PF\n2 3\n-1.0\n" + bytes(24), "truncated PFM .* expected 72 bytes"),
    ],
)
def test_corrupt(tmp_path, content, match):
    p = tmp_path / "bad.pfm"
    p.write_bytes(content)
    with pytest.raises(ValueError, match=match):
        read_pfm(p)


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.pfm"):
        read_pfm(tmp_path / "nope.pfm")


@pytest.mark.parametrize("shape", [(3,), (2, 2, 2), (2, 2, 4), (1, 2, 2, 3)])
def test_write_bad_shape(tmp_path, shape):
    with pytest.raises(ValueError, match=r"\(H, W\) or \(H, W, 3\)"):
        write_pfm(tmp_path / "x.pfm", np.zeros(shape))
