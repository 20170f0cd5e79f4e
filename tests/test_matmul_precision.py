"""Every matrix product and convolution of the chain asks for full float32 precision.

JAX's default lets a GPU compute float32 products with TensorFloat-32 inputs (a 10-bit
mantissa; bfloat16 passes on a TPU): pixel coordinates and focal lengths near 1000 then move
a reprojection by up to ~0.8 px, and filter responses and costs lose three decimal digits.
The CPU computes in full precision either way, so these tests read the traced programs
(jaxprs) instead of comparing numbers: every ``dot_general`` and ``conv_general_dilated`` on
floating-point operands must carry ``Precision.HIGHEST``.
"""

from __future__ import annotations

import jax
import jax.extend as jex
import jax.numpy as jnp
import numpy as np
from jax import lax

from mvedge_jax.diff import warp_by_depth
from mvedge_jax.pipeline import PipelineConfig, estimate_disparity_arrays
from mvedge_jax.solve import SolverConfig, solve_poisson

PRODUCTS = ("dot_general", "conv_general_dilated")


def _products(jaxpr) -> list:
    """``(primitive name, precision, operand dtypes)`` of every product in ``jaxpr`` and in
    the programs nested in its equations (jit, loops, conditionals, custom derivatives)."""
    found = []
    for eqn in jaxpr.eqns:
        if eqn.primitive.name in PRODUCTS:
            dtypes = tuple(str(v.aval.dtype) for v in eqn.invars)
            found.append((eqn.primitive.name, eqn.params.get("precision"), dtypes))
        for sub in jex.core.jaxprs_in_params(eqn.params):
            found.extend(_products(sub))
    return found


def _low_precision(found: list) -> list:
    highest = (lax.Precision.HIGHEST, lax.Precision.HIGHEST)
    out = []
    for name, precision, dtypes in found:
        if not all("float" in d for d in dtypes):
            continue  # integer products are exact
        if precision not in (highest, lax.Precision.HIGHEST):
            out.append((name, precision, dtypes))
    return out


def test_the_scan_sees_products_and_flags_a_default_precision_one():
    a = jnp.ones((3, 3), jnp.float32)
    default = _products(jax.make_jaxpr(lambda x: x @ x)(a).jaxpr)
    full = _products(jax.make_jaxpr(lambda x: jnp.matmul(x, x, precision="highest"))(a).jaxpr)
    assert len(default) == 1 and len(_low_precision(default)) == 1
    assert len(full) == 1 and _low_precision(full) == []


def test_whole_chain_uses_full_precision_products():
    views = jnp.zeros((5, 5, 24, 32, 3), jnp.float32)

    def chain(v):
        out = estimate_disparity_arrays(v, PipelineConfig(), key=jax.random.PRNGKey(0), d_max=2.0)
        return out.disparity

    found = _products(jax.make_jaxpr(chain)(views).jaxpr)
    # The EPI filter bank is a convolution and the surface profiles are products: the scan
    # must see them, or it proves nothing.
    assert {name for name, _, _ in found} == set(PRODUCTS)
    assert _low_precision(found) == []


def test_multigrid_solve_and_its_gradient_use_full_precision_products():
    rng = np.random.default_rng(0)
    H, W = 40, 48
    lam = jnp.asarray(rng.uniform(0, 1, (H, W)) * (rng.uniform(size=(H, W)) < 0.1), jnp.float32)
    target = jnp.asarray(rng.normal(size=(H, W)), jnp.float32)
    wx = jnp.ones((H, W - 1), jnp.float32)
    wy = jnp.ones((H - 1, W), jnp.float32)
    config = SolverConfig(preconditioner="multigrid")

    def loss(lam, target):
        return jnp.sum(solve_poisson(lam, target, wx, wy, config=config).x ** 2)

    found = _products(jax.make_jaxpr(jax.grad(loss, argnums=(0, 1)))(lam, target).jaxpr)
    assert any(name == "dot_general" for name, _, _ in found)  # the coarse-grid solve
    assert _low_precision(found) == []


def test_reprojection_uses_full_precision_products():
    dtype = jnp.float32
    H, W = 12, 16
    image = jnp.zeros((H, W, 3), dtype)
    depth = jnp.full((H, W), 5.0, dtype)
    K = jnp.asarray([[1000.0, 0, 8], [0, 1000.0, 6], [0, 0, 1]], dtype)
    R = jnp.eye(3, dtype=dtype)
    t = jnp.asarray([0.1, 0.0, 0.0], dtype)

    def warped(depth):
        return jnp.sum(warp_by_depth(image, depth, K, K, R, t)[0])

    for program in (jax.make_jaxpr(warped), jax.make_jaxpr(jax.grad(warped))):
        found = _products(program(depth).jaxpr)
        assert any(name == "dot_general" for name, _, _ in found)
        assert _low_precision(found) == []
