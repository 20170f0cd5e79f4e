"""Centre-view diffusion (eq 6.1): accuracy, surface vectors, gradients, jit, errors."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads
from reconstruct_helpers import two_region_view

from mvedge_jax.edges import HORIZONTAL, EdgeSet
from mvedge_jax.reconstruct import (
    CentreConfig,
    EpiConfig,
    FillConfig,
    OracleSurface,
    ReconstructConfig,
    SharpenConfig,
    centre_disparity,
)
from mvedge_jax.reconstruct._centre import centre_problem, uniform_window
from mvedge_jax.solve import SolverConfig


def _step_edges(H: int, split: int, d_left: float, d_right: float, dtype=np.float32):
    """Edge points on both boundary columns of a vertical step at ``split | split + 1``:
    the left column carries the left label (surface vector -x), the right one the right label
    (+x). Returns ``(EdgeSet, OracleSurface)`` without the confidence map."""
    ys = np.arange(H, dtype=dtype)
    x = np.concatenate([np.full(H, split), np.full(H, split + 1)]).astype(dtype)
    y = np.concatenate([ys, ys])
    d = np.concatenate([np.full(H, d_left), np.full(H, d_right)]).astype(dtype)
    n = 2 * H
    off = np.zeros((n, 2), dtype)
    off[:H, 0], off[H:, 0] = -1.0, 1.0
    return _points(x, y, d, dtype), jnp.asarray(off), jnp.ones(n, dtype)


def _points(xs, ys, d, dtype=np.float32) -> EdgeSet:
    """Valid, visible edge points of unit confidence from horizontal EPIs at ``(xs, ys)``
    with labels ``d``."""
    n = len(xs)
    return EdgeSet(
        x=jnp.asarray(xs),
        y=jnp.asarray(ys),
        disparity=jnp.asarray(d),
        confidence=jnp.ones(n, dtype),
        visible=jnp.ones(n, bool),
        lab=jnp.zeros((n, 3), dtype),
        direction=jnp.full(n, HORIZONTAL, jnp.int32),
        intercepts=jnp.zeros((n, 2), dtype),
        valid=jnp.ones(n, bool),
        n_dropped=jnp.zeros((), jnp.int32),
    )


def test_centre_oracle_accuracy(small_scene):
    lf, edges, surface = small_scene
    d = jax.jit(centre_disparity)(edges, surface, lf.centre_view, ReconstructConfig())
    mse = 100 * float(jnp.mean((d - lf.centre_gt) ** 2))
    bad = 100 * float(jnp.mean(jnp.abs(d - lf.centre_gt) > 0.07))
    assert d.shape == lf.centre_gt.shape and d.dtype == jnp.float32
    assert mse < 0.5, mse
    assert bad < 10.0, bad


def test_surface_vectors_sharpen_the_step():
    # Labels sit on the two boundary columns; offsetting them towards their own side keeps
    # the step where the colour edge is, splatting them in place still puts every label on
    # its own side here, but offsetting the wrong way swaps the sides of the boundary pixels.
    H, W, split = 24, 32, 15
    img = two_region_view(H, W, split)
    edges, off, step = _step_edges(H, split, 1.0, -1.0)
    conf = jnp.zeros((H, W))
    truth = np.where(np.arange(W)[None] <= split, 1.0, -1.0) * np.ones((H, 1))
    cfg = ReconstructConfig()
    errs = {}
    for name, o in (("right", off), ("wrong", -off)):
        d = centre_disparity(edges, OracleSurface(o, step, conf), img, cfg)
        errs[name] = float(jnp.mean(jnp.abs(d - truth)))
    assert errs["right"] < 0.02, errs
    assert errs["wrong"] > 5 * errs["right"], errs


def test_depth_edge_confidence_blocks_leakage():
    # Labels only at the far left and right borders; the colour edge is weak (0.001 in RGB,
    # a quarter of one 8-bit level) so without the confidence map the two labels blend
    # (measured: mean error 0.40); the depth-edge confidence on the boundary keeps the step
    # (0.001).
    H, W, split = 16, 40, 19
    img = np.full((H, W, 3), 0.5, np.float32)
    img[:, split + 1 :] += 0.001
    xs = np.concatenate([np.zeros(H), np.full(H, W - 1)]).astype(np.float32)
    ys = np.tile(np.arange(H, dtype=np.float32), 2)
    d = np.concatenate([np.full(H, 1.0), np.full(H, -1.0)]).astype(np.float32)
    n = 2 * H
    edges = _points(xs, ys, d)
    conf = np.zeros((H, W), np.float32)
    conf[:, split : split + 2] = 1.0
    truth = np.where(np.arange(W)[None] <= split, 1.0, -1.0) * np.ones((H, 1))
    z = jnp.zeros((n, 2))
    out = {}
    for beta in (0.0, 1000.0):
        cfg = ReconstructConfig(centre=CentreConfig(conf_beta=beta))
        dd = centre_disparity(edges, OracleSurface(z, jnp.ones(n), jnp.asarray(conf)), img, cfg)
        out[beta] = float(jnp.mean(jnp.abs(dd - truth)))
    assert out[1000.0] < 0.05, out
    assert out[0.0] > 0.3, out


def _panel_on_floor(floor_noise: float):
    """A uniform yellow panel (columns 0–19, disparity 1.2) on a tan floor (columns 20–39,
    disparity −1; Gaussian noise of ``floor_noise`` on it). The panel's boundary labels sit
    0.4 px inside the floor (their splat at ``p + n`` puts 0.4 of each label on column 20);
    the floor's only labels are at its right border."""
    H, W, split = 12, 40, 19
    img = np.empty((H, W, 3), np.float32)
    img[:, : split + 1] = [0.85, 0.75, 0.2]
    rng = np.random.default_rng(1)
    img[:, split + 1 :] = [0.7, 0.55, 0.4] + floor_noise * rng.normal(size=(H, W - split - 1, 3))
    img = img.clip(0, 1)
    ys = np.tile(np.arange(H, dtype=np.float32), 2)
    xs = np.concatenate([np.full(H, split + 1.4), np.full(H, W - 1.0)]).astype(np.float32)
    d = np.concatenate([np.full(H, 1.2), np.full(H, -1.0)]).astype(np.float32)
    n = 2 * H
    off = np.zeros((n, 2), np.float32)
    off[:, 0] = -1.0  # both point left: the panel's labels into the panel, the floor's into it
    edges = _points(xs, ys, d)
    surface = OracleSurface(jnp.asarray(off), jnp.ones(n), jnp.zeros((H, W)))
    truth = np.where(np.arange(W)[None] <= split, 1.2, -1.0) * np.ones((H, 1))
    return img, edges, surface, truth, split


def test_labels_keep_their_splat_off_a_uniform_region_across_the_edge():
    img, edges, surface, truth, split = _panel_on_floor(0.0)
    off = ReconstructConfig(centre=CentreConfig(splat_uniform=0.0))
    on = ReconstructConfig()
    lam_off = np.asarray(centre_problem(edges, surface, jnp.asarray(img), off)[0])
    lam_on = np.asarray(centre_problem(edges, surface, jnp.asarray(img), on)[0])
    # The floor column next to the panel loses the panel's weight, the panel keeps its own.
    assert np.all(lam_off[:, split + 1] > 0) and np.all(lam_on[:, split + 1] == 0)
    np.testing.assert_array_equal(lam_on[:, split], lam_off[:, split])
    floor = np.s_[:, split + 1 :]
    err = {}
    for name, cfg in (("off", off), ("on", on)):
        d = np.asarray(centre_disparity(edges, surface, img, cfg))
        err[name] = float(np.mean(np.abs(d - truth)[floor]))
        assert np.mean(np.abs(d - truth)[:, : split + 1]) < 0.05, (name, d[0])
    # Without the test the floor, which has no label near the panel, follows the stray
    # labels; with it, its own.
    assert err["on"] < 0.05 and err["off"] > 0.3, err


def test_splat_stays_bilinear_next_to_a_textured_region():
    img, edges, surface, _, _ = _panel_on_floor(0.1)
    assert float(uniform_window(jnp.asarray(img))[0, 25]) > 0.1
    lam = [
        np.asarray(centre_problem(edges, surface, jnp.asarray(img), cfg)[0])
        for cfg in (ReconstructConfig(centre=CentreConfig(splat_uniform=0.0)), ReconstructConfig())
    ]
    np.testing.assert_array_equal(lam[0], lam[1])


def _panel_floor_strip(floor_noise: float):
    """`_panel_on_floor` with the floor cut to a strip of three columns (20–22) before a
    blue wall (columns 23–39): the pixel 2 px across the panel's labels (column 22) lies
    on the strip, whose 3×3 windows all touch the panel or the wall, so the uniform-region
    test does not act."""
    img, edges, surface, truth, split = _panel_on_floor(floor_noise)
    img[:, split + 4 :] = [0.2, 0.3, 0.8]
    return img, edges, surface, split


def test_splat_side_ratio_drops_corners_that_show_the_other_side():
    img, edges, surface, split = _panel_floor_strip(0.0)
    assert float(uniform_window(jnp.asarray(img))[0, split + 2]) > 0.1  # no uniform region
    lam = {
        r: np.asarray(
            centre_problem(
                edges,
                surface,
                jnp.asarray(img),
                ReconstructConfig(centre=CentreConfig(splat_side_ratio=r)),
            )[0]
        )
        for r in (0.0, 0.1)
    }
    # Off: the strip's column next to the panel takes 0.4 of every panel label.
    assert np.all(lam[0.0][:, split + 1] > 0)
    # On: that corner has the colour of the pixel across the edge (the strip) and loses its
    # weight; the corner on the panel (the label's own colour) keeps its own.
    assert np.all(lam[0.1][:, split + 1] == 0)
    np.testing.assert_array_equal(lam[0.1][:, split], lam[0.0][:, split])
    np.testing.assert_array_equal(lam[0.1][:, split + 2 :], lam[0.0][:, split + 2 :])


def test_splat_side_ratio_keeps_corners_on_a_textured_strip():
    # With texture on the strip the corner's colour is no nearer the pixel across the edge
    # than a tenth of its distance to the panel's colour: the splat stays bilinear.
    img, edges, surface, split = _panel_floor_strip(0.1)
    lam = [
        np.asarray(centre_problem(edges, surface, jnp.asarray(img), cfg)[0])
        for cfg in (
            ReconstructConfig(),
            ReconstructConfig(centre=CentreConfig(splat_side_ratio=0.1)),
        )
    ]
    np.testing.assert_array_equal(lam[0], lam[1])


def test_uniform_window():
    img = np.full((6, 7, 3), 0.5, np.float32)
    img[:, 4:] = 0.8  # a step between columns 3 and 4
    g = np.asarray(uniform_window(jnp.asarray(img)))
    step = np.sqrt(3 * 0.3**2)
    np.testing.assert_allclose(g[:, 2:6], step, rtol=1e-6)  # 3×3 windows touching the step
    assert np.all(g[:, :2] == 0) and np.all(g[:, 6:] == 0)


def test_centre_gradients_wrt_hyperparameters(x64):
    H, W, split = 6, 8, 3
    img = jnp.asarray(two_region_view(H, W, split), jnp.float64)
    edges, off, _ = _step_edges(H, split, 0.7, -0.4, np.float64)
    step = jnp.linspace(0.1, 0.9, edges.capacity)
    conf = jnp.linspace(0.0, 1.0, H * W).reshape(H, W)
    surface = OracleSurface(off * 0.7, step, conf)
    solver = SolverConfig(preconditioner="jacobi", rtol=1e-13, max_iters=2000)
    # Perturb labels so that every hyperparameter matters.
    edges = EdgeSet(
        **{
            **{f: getattr(edges, f) for f in edges.__dataclass_fields__},
            "disparity": edges.disparity + jnp.linspace(-0.2, 0.3, edges.capacity),
        }
    )
    w = jnp.asarray(np.random.default_rng(0).normal(size=(H, W)))

    def loss(omega, a, c, beta):
        centre = CentreConfig(omega=omega, a=a, c=c, conf_beta=beta, solver=solver)
        cfg = ReconstructConfig(centre=centre)
        return jnp.sum(w * centre_disparity(edges, surface, img, cfg))

    args = (jnp.float64(2.0), jnp.float64(1.5), jnp.float64(0.8), jnp.float64(3.0))
    assert jnp.isfinite(jax.grad(loss, argnums=(0, 1, 2, 3))(*args)[0])
    check_grads(loss, args, order=1, modes=("rev",), eps=1e-6)


def test_centre_vmap_over_hyperparameter(small_scene):
    lf, edges, surface = small_scene
    f = jax.vmap(
        lambda om: centre_disparity(
            edges, surface, lf.centre_view, ReconstructConfig(centre=CentreConfig(omega=om))
        )
    )
    out = f(jnp.asarray([50.0, 150.0]))
    assert out.shape == (2,) + lf.centre_gt.shape
    cfg = ReconstructConfig(centre=CentreConfig(omega=50.0))
    single = centre_disparity(edges, surface, lf.centre_view, cfg)
    np.testing.assert_allclose(out[0], single, atol=2e-3)


def test_centre_upsampled_grid(small_scene):
    lf, edges, surface = small_scene
    cfg = ReconstructConfig(centre=CentreConfig(upsample=2))
    d = centre_disparity(edges, surface, lf.centre_view, cfg)
    assert d.shape == lf.centre_gt.shape
    assert 100 * float(jnp.mean((d - lf.centre_gt) ** 2)) < 1.0


def test_centre_bad_input(small_scene):
    lf, edges, surface = small_scene
    with pytest.raises(ValueError, match="centre_view"):
        centre_disparity(edges, surface, lf.centre_view[..., :2])
    bad = OracleSurface(surface.offset[:-1], surface.step_response, surface.depth_edge_confidence)
    with pytest.raises(ValueError, match="offset"):
        centre_disparity(edges, bad, lf.centre_view)
    bad = OracleSurface(surface.offset, surface.step_response, surface.depth_edge_confidence[:-1])
    with pytest.raises(ValueError, match="depth_edge_confidence"):
        centre_disparity(edges, bad, lf.centre_view)


@pytest.mark.parametrize(
    "cls, kwargs",
    [
        (CentreConfig, dict(omega=-1.0)),
        (CentreConfig, dict(eps=0.0)),
        (CentreConfig, dict(upsample=3)),
        (ReconstructConfig, dict(colour_space="hsv")),
        (SharpenConfig, dict(wmf_weight="x")),
        (FillConfig, dict(hole_fill="none")),
        (SharpenConfig, dict(wmf_radius=0)),
        (SharpenConfig, dict(wmf_slope_baseline=-1)),
        (SharpenConfig, dict(wmf_slope_max=-0.01)),
        (EpiConfig, dict(c=float("nan"))),
        (FillConfig, dict(min_confidence=-0.1)),
        (EpiConfig, dict(min_confidence=-0.1)),
        (FillConfig, dict(hole_weight=-1.0)),
        (FillConfig, dict(colour_margin=-0.1)),
        (EpiConfig, dict(colour_margin=-0.1)),
    ],
)
def test_config_validation(cls, kwargs):
    with pytest.raises(ValueError):
        cls(**kwargs)
