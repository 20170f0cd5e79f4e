"""`edge_pad`: the values of ``jnp.pad(mode="edge")``, fused into its consumers."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from mvedge_jax._pad import edge_pad


@pytest.mark.parametrize(
    ("shape", "width"),
    [
        ((5, 7), 2),
        ((5, 7), ((1, 3), (0, 2))),
        ((3, 4, 2), ((0, 0), (2, 2), (1, 1))),
        ((2, 3, 4, 3), ((0, 0), (0, 3), (4, 0), (0, 0))),
        ((1, 6), ((2, 1), (0, 0))),  # one row repeated
        ((4,), (3,)),
        ((4, 4), 0),
    ],
)
def test_equals_jnp_pad_edge(shape, width):
    rng = np.random.default_rng(sum(shape))
    x = rng.normal(size=shape).astype(np.float32)
    x.flat[0] = np.nan  # a corner that the padding repeats
    want = np.pad(x, width, mode="edge")
    got = np.asarray(jax.jit(lambda a: edge_pad(a, width))(x))
    assert got.shape == want.shape and got.dtype == want.dtype
    np.testing.assert_array_equal(got, want)


def test_integer_and_bool():
    x = np.arange(12, dtype=np.int32).reshape(3, 4)
    np.testing.assert_array_equal(edge_pad(x, 1), np.pad(x, 1, mode="edge"))
    b = x % 3 == 0
    width = ((2, 0), (0, 1))
    np.testing.assert_array_equal(edge_pad(b, width), np.pad(b, width, mode="edge"))


def test_gradient_gathers_the_border():
    x = jnp.asarray(np.random.default_rng(0).normal(size=(4, 5)))
    check_grads(lambda a: jnp.sum(edge_pad(a, 2) ** 2), (x,), order=2, modes=("fwd", "rev"))
    # The corner value is repeated (2 + 1)² times, so d/dx of the sum is 9 there.
    g = jax.grad(lambda a: jnp.sum(edge_pad(a, 2)))(x)
    assert g[0, 0] == 9 and g[1, 1] == 1 and g[0, 2] == 3


@pytest.mark.parametrize(
    ("width", "message"),
    [(-1, ">= 0"), (((1, 1), (1, 1), (1, 1)), "broadcast"), (((1, -2), (0, 0)), ">= 0")],
)
def test_rejects_bad_widths(width, message):
    with pytest.raises(ValueError, match=message):
        edge_pad(np.zeros((3, 3)), width)


def test_rejects_empty_axis():
    with pytest.raises(ValueError, match="size 0"):
        edge_pad(np.zeros((0, 3)), 1)
    assert edge_pad(np.zeros((0, 3)), ((0, 0), (1, 1))).shape == (0, 5)
