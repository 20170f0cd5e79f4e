"""Gradients of the whole chain against central finite differences, one test per field.

The loss is the mean squared disparity error of every view of a small synthetic light field
against its exact ground truth, through `estimate_disparity_arrays` in float64 with the
`smooth_config` surrogates (soft edge labels → surface vectors → centre diffusion →
weighted-mean sharpening → cross-hair projection, EPI inpainting and off-cross-hair fill).
One reverse-mode gradient with respect to every differentiable field at once, then the loss
at two or more points per field (by a forward-only program of the same loss). The solvers run
to a 1e-12 relative residual so that finite differences are not limited by the solver's
tolerance. They pass on the CPU; on an H200 with deterministic kernels the chain's reverse
pass is off (docs/RESULTS.md, "Deterministic kernels: speed and gradients"), and
`experiments/chain_gradients.py` prints the comparison per field.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mvedge_jax.edges import detect_edges_arrays, resolve_d_max
from mvedge_jax.pipeline import (
    PipelineConfig,
    estimate_disparity_arrays,
    get_path,
    hyperparameter_paths,
    replace_paths,
    smooth_config,
    with_values,
)
from mvedge_jax.solve import SolverConfig
from mvedge_jax.synthetic import make_scene

SMOOTH_PATHS = hyperparameter_paths(differentiable=True)
#: Relative step of the central differences, and the tolerance of the comparison.
REL_STEP = 1e-6
RTOL = 1e-3


def _tight(config: PipelineConfig) -> PipelineConfig:
    """Solvers to a 1e-12 residual; a test point where every field acts smoothly (anti-aliased
    bank, λ_e clipped for some points, splat offsets off the pixel grid, photo-consistent
    samples of the centre diffusion close enough to the labels to exist in a 32² view, no
    reprojected pixel's photometric confidence within the finite-difference step of the
    cross-hair threshold ``epi.min_confidence``: at the default 0.1 one is, and
    ``epi.photo_sigma`` ± 1e-7 flips it; the cross-hair holes' colour choice at margin 0:
    with the margins 0.25–0.35 a discrete choice of the cross-hair fill flips within the step
    of ``edges.filter.edge_shift``, whose difference quotient is then −0.069 against a
    gradient of 0.0024)."""
    tight = SolverConfig(rtol=1e-12, max_iters=5000)
    tight_j = SolverConfig(preconditioner="jacobi", rtol=1e-12, max_iters=20000)
    return with_values(
        config,
        {
            "edges.filter.aa_sigma": 0.3,
            "surface.solver": tight,
            "reconstruct.centre.lambda_e_max": 0.2,
            "reconstruct.centre.offset_scale": 0.93,
            "reconstruct.centre.solver": tight,
            "reconstruct.seeds.min_distance": 2,
            "reconstruct.epi.min_confidence": 0.12,
            "reconstruct.epi.colour_margin": 0.0,
            "reconstruct.epi.solver": tight_j,
            "reconstruct.fill.solver": tight_j,
        },
    )


@pytest.fixture(scope="module")
def x64_module():
    jax.config.update("jax_enable_x64", True)
    try:
        yield
    finally:
        jax.config.update("jax_enable_x64", False)


@pytest.fixture(scope="module")
def scene(x64_module):
    lf = make_scene(3, grid=(5, 5), size=(32, 32), disparity_range=(-1.0, 1.0), n_objects=3)
    views = jnp.asarray(lf.views, jnp.float64)
    gt = jnp.asarray(lf.gt_disparity, jnp.float64)
    return lf, views, gt


@pytest.fixture(scope="module")
def chain(scene):
    """``(values0, loss, loss0, gradient)``: the field values, the jitted loss (a float), its
    value at ``values0`` and its gradient there."""
    lf, views, gt = scene
    config = _tight(smooth_config())
    d_max = resolve_d_max(config.edges, lf.disparity_range)
    values0 = {p: jnp.asarray(get_path(config, p), jnp.float64) for p in SMOOTH_PATHS}

    def loss(values, views, gt):
        c = replace_paths(config, values)
        out = estimate_disparity_arrays(views, c, key=jax.random.key(0), d_max=d_max)
        return jnp.mean((out.disparity - gt) ** 2)

    value, grad = jax.jit(jax.value_and_grad(loss))(values0, views, gt)
    assert np.isfinite(float(value))
    # The finite differences' values come from a forward-only program: with the test run's
    # unoptimised machine code (tests/conftest.py) it compiles in a third of the gradient
    # program's time and runs five times faster, and the differences of the 35 fields take 71
    # values or more.
    loss_only = jax.jit(loss)

    def f(v):
        return float(loss_only(v, views, gt))

    loss0 = f(values0)
    np.testing.assert_allclose(loss0, float(value), rtol=1e-9)  # the two programs agree
    return values0, f, loss0, {p: float(g) for p, g in grad.items()}


#: Relative steps of the finite differences, tried in this order.
REL_STEPS = (REL_STEP, REL_STEP / 10, REL_STEP * 10)


def _central_difference(f, values0, f0, path):
    """Central difference at the first step of `REL_STEPS` whose two one-sided differences
    agree to `RTOL`.

    The loss is smooth only piecewise: where one of the chain's discrete choices flips (a
    solver's stopping iteration at the 1e-12 relative residual may be one), it jumps, by a few
    1e-11 within 1e-6 of some fields' values when the test run compiles unoptimised machine
    code. A bracket that holds such a jump shows it as a forward and a backward difference
    that disagree (at 1e-6, ``edges.filter.edge_shift``'s 4.677e-3 and 4.641e-3 against a
    gradient of 4.641e-3, which the central difference at 1e-7 matches); the next step is
    tried then. Without such a step, the first one's central difference is returned.
    """
    x = float(values0[path])
    first = None
    for rel in REL_STEPS:
        h = rel * max(abs(x), 1e-2)
        up, down = dict(values0), dict(values0)
        up[path] = values0[path] + h
        down[path] = values0[path] - h
        f_up, f_down = f(up), f(down)
        ahead, behind = (f_up - f0) / h, (f0 - f_down) / h
        central = (f_up - f_down) / (2 * h)
        if abs(ahead - behind) <= RTOL * max(abs(ahead), abs(behind)):
            return central
        first = central if first is None else first
    return first


@pytest.mark.parametrize("path", SMOOTH_PATHS)
def test_chain_gradient_matches_finite_differences(chain, path):
    values0, f, f0, grad = chain
    fd = _central_difference(f, values0, f0, path)
    ad = grad[path]
    assert ad != 0.0, f"{path}: zero gradient where the loss depends on it (fd {fd:.3e})"
    assert abs(ad - fd) <= RTOL * max(abs(ad), abs(fd)), f"{path}: ad {ad:.6e} fd {fd:.6e}"


@pytest.mark.parametrize("path", ["edges.filter.presmooth_sigma"])
def test_hard_edge_labels_gradient_matches_finite_differences(scene, path):
    """The default (hard) labels are piecewise smooth: where no discrete choice flips, their
    gradient is exact."""
    lf, views, _ = scene
    d_max = resolve_d_max(PipelineConfig().edges, lf.disparity_range)
    row, col = views[2], views[:, 2]

    def labels(v):
        e = detect_edges_arrays(
            row,
            col,
            replace_paths(PipelineConfig(), {path: v}).edges,
            d_max=d_max,
            key=jax.random.key(0),
        )
        return jnp.sum(jnp.where(e.valid, e.disparity, 0.0))

    x0 = jnp.asarray(float(get_path(PipelineConfig(), path)), jnp.float64)
    value_and_grad = jax.jit(jax.value_and_grad(labels))
    ad = float(value_and_grad(x0)[1])
    h = REL_STEP * abs(float(x0))
    fd = (float(value_and_grad(x0 + h)[0]) - float(value_and_grad(x0 - h)[0])) / (2 * h)
    assert ad != 0.0
    assert abs(ad - fd) <= RTOL * max(abs(ad), abs(fd)), f"ad {ad:.6e} fd {fd:.6e}"
