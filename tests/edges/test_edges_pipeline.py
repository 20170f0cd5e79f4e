"""`detect_edges` end to end on synthetic light fields: accuracy, overflow, bad input, jit."""

from __future__ import annotations

import dataclasses
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mvedge_jax.edges import (
    HORIZONTAL,
    VERTICAL,
    EdgeConfig,
    EdgeRefineConfig,
    EdgeSet,
    FilterConfig,
    LabelConfig,
    OutlierConfig,
    detect_edges,
    point_errors,
    render_sparse_disparity,
)
from mvedge_jax.lightfield import LightField


@pytest.fixture(scope="module")
def plane():
    from edges_helpers import plane_light_field

    return plane_light_field(0.637, H=40, W=56)


@pytest.fixture(scope="module")
def plane_edges(plane):
    return detect_edges(plane)


def test_plane_disparity_recovered(plane, plane_edges):
    e = plane_edges
    assert isinstance(e, EdgeSet)
    assert e.capacity == 40 * 56 + 56 * 40
    v = np.asarray(e.valid)
    dirs = np.asarray(e.direction)
    # Points from both EPI directions; the plane's disparity to a few thousandths.
    assert (v & (dirs == HORIZONTAL)).sum() > 100 and (v & (dirs == VERTICAL)).sum() > 100
    d = np.asarray(e.disparity)[v]
    assert np.median(np.abs(d - 0.637)) < 3e-3
    assert np.mean(np.abs(d - 0.637) < 0.02) > 0.95
    err = np.asarray(point_errors(e, plane.centre_gt))
    assert np.nanmax(err) == pytest.approx(np.abs(d - 0.637).max())
    assert int(e.n_dropped) == 0
    # Geometry of the outputs.
    x, y = np.asarray(e.x)[v], np.asarray(e.y)[v]
    assert x.min() >= 0 and x.max() <= 55 and y.min() >= 0 and y.max() <= 39
    it = np.asarray(e.intercepts)[v]
    np.testing.assert_allclose(it[:, 0] - it[:, 1], 8 * d, atol=1e-4)  # 9 views: xt - xb = 8 d
    lab = np.asarray(e.lab)[v]
    assert lab[:, 0].min() >= 0 and lab[:, 0].max() <= 100


def test_overflow_counted_and_warned_thesis_style(plane):
    # Thesis-style detection (NMS, λ = 0.2h line fitting, labels only, alignment and visibility
    # tests): runs without warnings when nothing overflows ...
    label = dict(nms=True, lambda_frac=0.2, subpixel="none", min_ratio=0.0)
    thesis = EdgeConfig(
        label=LabelConfig(**label),
        outliers=OutlierConfig(enabled=False),
        refine=EdgeRefineConfig(trilateral=False, gradient_alignment=True, drop_invisible=True),
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        full = detect_edges(plane, thesis)
    v = np.asarray(full.valid)
    assert v.sum() > 100 and int(full.n_dropped) == 0
    assert np.median(np.abs(np.asarray(full.disparity)[v] - 0.637)) < 0.05
    # ... and with 2 slots per EPI the strongest candidates are kept, the rest counted, warned.
    with pytest.warns(UserWarning, match="did not fit"):
        capped = dataclasses.replace(thesis, label=LabelConfig(**label, line_capacity=2))
        e = detect_edges(plane, capped)
    assert e.capacity == 2 * (40 + 56)
    assert int(e.n_dropped) > 0
    # Every dropped candidate was an NMS maximum above min_confidence; kept ones fill the slots.
    n_kept = int(np.asarray(e.valid).sum())
    assert n_kept <= 2 * (40 + 56)
    assert int(e.n_dropped) + 2 * (40 + 56) >= v.sum()


def test_bad_inputs(plane):
    with pytest.raises(ValueError, match="cannot cover|covers"):
        detect_edges(plane, EdgeConfig(filter=FilterConfig(d_max=0.3)))  # range up to 1.137
    bad = eqx.tree_at(lambda lf: lf.views, plane, plane.views.at[4, 4, 3, 3, 0].set(jnp.nan))
    with pytest.raises(ValueError, match="NaN"):
        detect_edges(bad)
    with pytest.raises(ValueError, match="at least 3"):
        LightField(views=plane.views[:2], view_mask=jnp.ones((2, 9), bool))
    with pytest.raises(ValueError, match="too much"):
        detect_edges(plane, EdgeConfig(filter=FilterConfig(d_max=6.0)))
    with pytest.raises(ValueError):
        LabelConfig(subpixel="cubic")
    with pytest.raises(ValueError):
        FilterConfig(n_filters=2)
    with pytest.raises(ValueError):
        LabelConfig(line_capacity=0)
    with pytest.raises(ValueError):
        FilterConfig(presmooth_sigma=-1.0)


def test_jit_end_to_end(plane, plane_edges):
    f = jax.jit(
        lambda views: detect_edges(
            LightField(
                views=views, view_mask=plane.view_mask, disparity_range=plane.disparity_range
            )
        )
    )
    a = f(plane.views)
    b = plane_edges
    assert a.capacity == b.capacity == 2 * 40 * 56
    np.testing.assert_array_equal(np.asarray(a.valid), np.asarray(b.valid))
    np.testing.assert_allclose(np.asarray(a.disparity), np.asarray(b.disparity), atol=1e-5)
    d, m = jax.jit(lambda e: render_sparse_disparity(e, (40, 56)))(a)
    assert d.shape == (40, 56) and m.dtype == jnp.bool_ and int(m.sum()) > 100
    np.testing.assert_allclose(np.asarray(d)[np.asarray(m)], 0.637, atol=0.02)


@pytest.mark.slow
def test_all_stages_together():
    # Every optional stage runs together and keeps a plane accurate (slow: compiles them all).
    from edges_helpers import plane_light_field

    plane = plane_light_field(0.637, H=24, W=40, seed=3)
    cfg = EdgeConfig(
        label=LabelConfig(nms=True, lambda_frac=0.2),
        outliers=OutlierConfig(enabled=True, tau=0.0),
        refine=EdgeRefineConfig(
            gradient_alignment=True,
            entropy_search=True,
            trilateral=True,
            trilateral_radius=3,
            multiscale=True,
        ),
    )
    e = detect_edges(plane, cfg, key=jax.random.key(1))
    # fine: one slot per centre-row pixel; coarse: one per coarse pixel, repeated on 2 EPIs
    assert e.capacity == (24 * 40 + 24 * 20) + (40 * 24 + 40 * 12)
    v = np.asarray(e.valid)
    assert v.sum() > 50
    assert np.median(np.abs(np.asarray(e.disparity)[v] - 0.637)) < 0.02
