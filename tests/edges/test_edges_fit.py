"""Line fitting (4.1.2): confidence order, perpendicular-distance suppression."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from mvedge_jax.edges import fit_lines


def test_suppression_along_x():
    # Candidates sorted by confidence; same row, vertical lines (d = 0).
    x = jnp.array([10.0, 11.0, 12.5, 20.0, 10.5])
    u = jnp.full((5,), 4.0)
    d = jnp.zeros((5,))
    acc = np.asarray(fit_lines(u, x, d, jnp.ones(5, bool), 1.8))
    # 11 (1 px) and 10.5 are within λ of the line at 10; 12.5 is 2.5 px away; 20 far.
    assert acc.tolist() == [True, False, True, True, False]
    assert np.asarray(fit_lines(u, x, d, jnp.ones(5, bool), 0.0)).all()


def test_perpendicular_distance_uses_slope():
    # Line through (u=4, x=10) with d = 2: x(u) = 10 - 2 (u - 4). Candidate on another row that
    # lies on the line is suppressed; one 2 px off along x is 2/sqrt(5) = 0.89 px away.
    u = jnp.array([4.0, 6.0, 6.0, 6.0])
    x = jnp.array([10.0, 6.0, 8.0, 9.0])
    d = jnp.array([2.0, 2.0, 2.0, 2.0])
    acc = np.asarray(fit_lines(u, x, d, jnp.ones(4, bool), 0.8))
    # x = 6 on row 6 lies on the first line; x = 8 is 2/sqrt(5) = 0.89 > 0.8 from it and starts
    # a line; x = 9 is 3/sqrt(5) = 1.34 from the first line but 1/sqrt(5) = 0.45 from the second.
    assert acc.tolist() == [True, False, True, False]


def test_invalid_candidates_never_suppress_and_vmap():
    x = jnp.array([[10.0, 10.5, 30.0], [5.0, 5.2, 5.4]])
    u = jnp.full((2, 3), 4.0)
    d = jnp.zeros((2, 3))
    valid = jnp.array([[False, True, True], [True, True, True]])
    acc = np.asarray(jax.jit(jax.vmap(fit_lines, in_axes=(0, 0, 0, 0, None)))(u, x, d, valid, 1.0))
    assert acc.tolist() == [[False, True, True], [True, False, False]]
