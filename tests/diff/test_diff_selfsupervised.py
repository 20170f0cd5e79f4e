"""Self-supervised optimisation with the warping loss of eq 7.16 on a synthetic light field."""

from __future__ import annotations

import numpy as np
import pytest

from mvedge_jax.diff import (
    OptimizeConfig,
    image_gradient_magnitude,
    initial_params,
    optimize,
    predict,
)
from mvedge_jax.synthetic import make_scene


@pytest.mark.slow
def test_self_supervised_optimisation_reduces_the_disparity_error():
    lf = make_scene(4, grid=(5, 5), size=(64, 64))
    img, gt = np.asarray(lf.centre_view), np.asarray(lf.centre_gt)
    U, V = lf.grid
    others, offs = [], []
    for r in range(U):
        for c in range(V):
            if (r == U // 2) != (c == V // 2):  # the cross-hair without the centre
                others.append(np.asarray(lf.views[r, c]))
                offs.append((r - U // 2, c - V // 2))
    mag = np.asarray(image_gradient_magnitude(img))
    idx = np.argsort(mag.ravel())[::-1][:800]
    yy, xx = np.unravel_index(idx, gt.shape)
    rng = np.random.default_rng(0)
    pos = np.stack([xx, yy], 1).astype(np.float32)
    lab = (gt[yy, xx] + rng.normal(0, 0.3, len(idx))).astype(np.float32)
    cfg = OptimizeConfig(iterations=10, passes=2)
    p0 = initial_params(pos, lab, img, cfg.model)
    _, hist = optimize(p0, img, np.stack(others), np.asarray(offs, np.float32), cfg)
    d0 = np.asarray(predict(p0, cfg.model).disparity)
    mse0 = 100 * np.mean((d0 - gt) ** 2)
    mse = 100 * np.mean((hist["disparity"] - gt) ** 2)
    assert hist["loss"][-1] < hist["loss"][0]
    assert mse < 0.7 * mse0
