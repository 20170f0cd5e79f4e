"""Accuracy of `detect_edges` on a real scene with ground truth (a band of backgammon rows)."""

from __future__ import annotations

import equinox as eqx
import numpy as np

from mvedge_jax.edges import detect_edges, point_errors
from mvedge_jax.io import read_hci4d


def test_backgammon_band_accuracy(data_dir):
    lf = read_hci4d(data_dir / "hci4d" / "stratified" / "backgammon")
    rows = slice(192, 256)  # both colours of stripes and the grey background
    lf = eqx.tree_at(
        lambda f: (f.views, f.gt_disparity, f.gt_mask),
        lf,
        (lf.views[:, :, rows], lf.gt_disparity[:, :, rows], lf.gt_mask[:, :, rows]),
    )
    e = detect_edges(lf)
    err = np.asarray(point_errors(e, lf.centre_gt, lf.centre_gt_mask))
    v = np.asarray(e.valid)
    err = err[v]
    # Measured on this band (default config): 18.9k points, median 0.0026 px, 99.9 % < 0.1 px.
    assert v.sum() > 14_000
    assert np.median(err) < 0.005
    assert np.mean(err < 0.1) > 0.99
    h = v & (np.asarray(e.direction) == 0)
    assert h.sum() > 0.4 * v.sum()
