"""`map_where`: ``lax.map`` of a step where a flag holds, a fallback elsewhere."""

import jax
import jax.numpy as jnp
import numpy as np

from mvedge_jax._loop import map_where


def _step(x):
    a, b = x
    return jnp.sin(a) * b + jnp.roll(a, 1), jnp.sum(a * b)


def _keep(x):
    return x[0], jnp.zeros((), x[0].dtype)


def test_runs_where_flagged_and_keeps_elsewhere():
    rng = np.random.default_rng(0)
    a = jnp.asarray(rng.normal(size=(5, 7)), jnp.float32)
    b = jnp.asarray(rng.normal(size=(5, 7)), jnp.float32)
    run = jnp.asarray([True, False, True, True, False])
    got = jax.jit(map_where, static_argnums=(0, 1))(_step, _keep, run, (a, b))
    want = jax.lax.map(_step, (a, b))
    for k in range(5):
        if run[k]:
            np.testing.assert_array_equal(got[0][k], want[0][k])
            np.testing.assert_array_equal(got[1][k], want[1][k])
        else:
            np.testing.assert_array_equal(got[0][k], a[k])
            assert got[1][k] == 0


def test_under_vmap_and_grad():
    a = jnp.linspace(0.0, 1.0, 12).reshape(2, 3, 2)
    b = jnp.ones_like(a)
    run = jnp.asarray([[True, False, True], [False, True, True]])
    out = jax.vmap(lambda r, x, y: map_where(_step, _keep, r, (x, y))[1])(run, a, b)
    want = jnp.where(run, jnp.sum(a * b, axis=-1), 0.0)
    np.testing.assert_allclose(out, want, rtol=1e-6)
    g = jax.grad(lambda x: jnp.sum(map_where(_step, _keep, run[0], (x, b[0]))[1]))(a[0])
    np.testing.assert_allclose(g, jnp.where(run[0][:, None], b[0], 0.0))
