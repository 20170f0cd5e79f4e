"""A disparity range narrower than the scene is detected from the edge labels alone
(`check_range_saturation`), on a real scene whose metadata range is falsified."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mvedge_jax import load_light_field
from mvedge_jax.edges import EdgeConfig, detect_edges, resolve_d_max
from mvedge_jax.pipeline._checks import MAX_SATURATED_FRACTION, check_range_saturation


def test_saturation_counts_labels_at_the_bank_end():
    d = np.array([0.0, 0.5, -0.99, 1.0, 0.2, np.nan])
    valid = np.array([True, True, True, True, True, False])
    # spacing 2 * 1 / 20 = 0.1: |d| >= 0.9 counts
    frac, warnings = check_range_saturation("s", d, valid, 1.0, 21)
    assert frac == pytest.approx(2 / 5)
    assert len(warnings) == 1 and "40.0% of the edge points of 's'" in warnings[0]
    frac, warnings = check_range_saturation("s", d[:3], valid[:3], 2.0, 21)
    assert frac == 0.0 and warnings == []
    assert check_range_saturation("s", d, np.zeros(6, bool), 1.0, 21) == (0.0, [])


@pytest.fixture(scope="module")
def antinous(data_dir):
    return load_light_field(data_dir / "hci4d" / "additional" / "antinous", scale=0.5)


@pytest.mark.parametrize("factor", [1.0, 0.5])
def test_falsified_metadata_range_is_detected(antinous, factor):
    lo, hi = antinous.disparity_range
    lf = dataclasses.replace(antinous, disparity_range=(lo * factor, hi * factor))
    cfg = EdgeConfig()
    d_max = resolve_d_max(cfg, lf.disparity_range)
    e = detect_edges(lf, cfg)
    frac, warnings = check_range_saturation(
        lf.name, e.disparity, e.valid, d_max, cfg.filter.n_filters
    )
    if factor == 1.0:
        # Measured: 0 of 11.5k points (the default d_margin keeps the range's extremes inside).
        assert frac <= MAX_SATURATED_FRACTION and warnings == []
    else:
        # Measured: 12% of 8.3k points within one filter spacing of ±d_max.
        assert frac > 5 * MAX_SATURATED_FRACTION
        assert "probably wider than the one used" in warnings[0]
