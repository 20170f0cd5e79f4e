"""Block-coordinate Adam (thesis Sec. 7.1.5) with the supervised loss (Sec. 7.2.3)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from mvedge_jax.diff import (
    BLOCKS,
    ModelConfig,
    OptimizeConfig,
    RenderConfig,
    image_gradient_magnitude,
    initial_params,
    optimize,
    params_from_edges,
)
from mvedge_jax.edges import EdgeSet
from mvedge_jax.synthetic import make_scene


def _laplacian(a):
    p = np.pad(a, 1, mode="edge")
    return p[:-2, 1:-1] + p[2:, 1:-1] + p[1:-1, :-2] + p[1:-1, 2:] - 4 * a


def _encode(img, gt, n, rng, noise):
    """Points at the strongest image-gradient / depth-curvature pixels, noisy labels."""
    mag = np.asarray(image_gradient_magnitude(img))
    lap = np.abs(_laplacian(gt))
    score = np.maximum(lap / np.percentile(lap, 95), mag / np.percentile(mag, 95))
    idx = np.argsort(score.ravel())[::-1][:n]
    yy, xx = np.unravel_index(idx, gt.shape)
    pos = np.stack([xx, yy], 1).astype(np.float32)
    return pos, (gt[yy, xx] + rng.normal(0.0, noise, n)).astype(np.float32)


@pytest.fixture(scope="module")
def supervised_run():
    lf = make_scene(0, grid=(3, 3), size=(32, 32))
    img, gt = np.asarray(lf.centre_view), np.asarray(lf.centre_gt)
    pos, lab = _encode(img, gt, 250, np.random.default_rng(0), noise=0.3)
    # one capacity level large enough for this dense point set (no overflow)
    model = ModelConfig(render=RenderConfig(tile_levels=((128, 1.0),)))
    cfg = OptimizeConfig(model=model, iterations=8, passes=2)
    p0 = initial_params(pos, lab, img, cfg.model)
    params, hist = optimize(p0, img, None, None, cfg, target_disparity=gt)
    return gt, p0, params, hist, cfg


def test_supervised_optimisation_reduces_mse_tenfold(supervised_run):
    gt, p0, params, hist, cfg = supervised_run
    final = 100.0 * np.mean((hist["disparity"] - gt) ** 2)
    assert hist["mse_x100"][0] > 10.0  # noisy labels: a bad start
    assert final <= 0.1 * hist["mse_x100"][0]
    # every block moved, the loss went down
    for name in BLOCKS:
        assert not np.allclose(np.asarray(getattr(params, name)), np.asarray(getattr(p0, name)))
    assert hist["loss"][-1] < 0.3 * hist["loss"][0]


def test_history_layout(supervised_run):
    _, _, _, hist, cfg = supervised_run
    n = cfg.passes * len(cfg.blocks) * cfg.iterations
    for key in (
        "loss",
        "mse_x100",
        "pass",
        "block",
        "solver_iterations",
        "solver_residual",
        "overflow",
        "seconds",
    ):
        assert hist[key].shape == (n,), key
    assert list(hist["block"][:: cfg.iterations]) == [0, 1, 2, 3] * cfg.passes
    assert hist["solver_residual"].max() < 1e-4 and hist["overflow"].max() == 0


def test_schedule_and_config_validation():
    cfg = OptimizeConfig(passes=2, blocks=("label", "Q"))
    sched = cfg.schedule()
    assert [(k, b) for k, b, _ in sched] == [(0, "label"), (0, "Q"), (1, "label"), (1, "Q")]
    np.testing.assert_allclose(float(sched[2][2]), 0.015 * 0.9, rtol=1e-6)
    with pytest.raises(ValueError, match="blocks"):
        OptimizeConfig(blocks=("depth",))
    with pytest.raises(ValueError, match=r"\(4,\)"):
        OptimizeConfig(learning_rate=(0.1, 0.1))
    with pytest.raises(ValueError, match="target_disparity"):
        optimize(
            initial_params(jnp.zeros((2, 2)), jnp.zeros(2), jnp.zeros((8, 8, 3))),
            jnp.zeros((8, 8, 3)),
            None,
            None,
        )


def test_params_from_edgeset():
    e = EdgeSet.empty(4)
    e = EdgeSet(
        x=jnp.array([1.0, 2.5, 3.0, 0.0]),
        y=jnp.array([2.0, 1.0, 3.5, 0.0]),
        disparity=jnp.array([0.5, -0.5, 1.0, 9.0]),
        confidence=e.confidence,
        visible=e.visible,
        lab=e.lab,
        direction=e.direction,
        intercepts=e.intercepts,
        valid=jnp.array([True, True, True, False]),
        n_dropped=e.n_dropped,
    )
    img = jnp.zeros((6, 7, 3))
    p, valid = params_from_edges(e, img)
    np.testing.assert_allclose(np.asarray(p.position[1]), [2.5, 1.0])
    assert p.Q.shape == (6, 7) and list(np.asarray(valid)) == [True, True, True, False]
    dense = jnp.arange(42.0).reshape(6, 7)
    p2, _ = params_from_edges(e, img, disparity=dense)
    assert float(p2.label[0]) == pytest.approx(15.0) and float(p2.label[3]) == 0.0
