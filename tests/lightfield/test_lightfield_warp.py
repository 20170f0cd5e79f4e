"""backward_warp / forward_project: behaviour, cracks vs disocclusions, shapes, jit, grads."""

from __future__ import annotations

import functools
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from mvedge_jax.lightfield import (
    GpuCompileWarning,
    _warp,
    backward_warp,
    backward_warp_planar,
    forward_project,
    forward_project_views,
)

H, W = 24, 32


def _grid(h=H, w=W):
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    return ys, xs


# ---- backward_warp ---------------------------------------------------------------------------


def test_backward_warp_zero_offset_and_zero_disparity_are_identity(key):
    img = jax.random.uniform(key, (H, W, 3))
    d = jax.random.normal(key, (H, W))
    np.testing.assert_allclose(backward_warp(img, d, (0.0, 0.0)), img, atol=1e-6)
    np.testing.assert_allclose(backward_warp(img, 0 * d, (2.0, -3.0)), img, atol=1e-6)


def test_backward_warp_integer_shift_sign():
    # Target(x, y) = view(x - dc*d, y - dr*d): with d = 1 and (dr, dc) = (1, 2) the target
    # pixel (x, y) reads view pixel (x - 2, y - 1).
    img = np.arange(H * W, dtype=np.float32).reshape(H, W)
    out = np.asarray(backward_warp(img, np.ones((H, W), np.float32), (1.0, 2.0)))
    np.testing.assert_array_equal(out[1:, 2:], img[:-1, :-2])
    # Border clamp: the first two columns read column 0.
    np.testing.assert_array_equal(out[1:, 0], img[:-1, 0])
    np.testing.assert_array_equal(out[1:, 1], img[:-1, 0])


def test_backward_warp_bilinear_by_hand():
    img = np.array([[0.0, 10.0, 20.0], [30.0, 40.0, 50.0], [60.0, 70.0, 80.0]], np.float32)
    d = np.full((3, 3), 0.5, np.float32)
    # offset (dr, dc) = (-0.5, -1): sample at (x + 0.5, y + 0.25)
    out = np.asarray(backward_warp(img, d, (-0.5, -1.0)))
    # pixel (x=0, y=0) samples (0.5, 0.25): 0.75*(0+10)/2 + 0.25*(30+40)/2 = 3.75 + 8.75
    assert out[0, 0] == pytest.approx(12.5, abs=1e-5)
    # pixel (x=1, y=1) samples (1.5, 1.25): 0.75*45 + 0.25*75 = 52.5
    assert out[1, 1] == pytest.approx(52.5, abs=1e-5)
    # pixel (x=2, y=2) samples (2.5, 2.25) → clamped to (2, 2)
    assert out[2, 2] == pytest.approx(80.0, abs=1e-5)


def test_backward_warp_dtype_and_channels(key):
    img = jax.random.uniform(key, (H, W, 5))
    out = backward_warp(img, jnp.full((H, W), 0.3), jnp.array([1.0, -1.0]))
    assert out.shape == (H, W, 5) and out.dtype == jnp.float32


def test_backward_warp_bad_shapes():
    with pytest.raises(ValueError, match="spatial shape"):
        backward_warp(np.zeros((H, W, 3)), np.zeros((H, W + 1)), (0.0, 1.0))
    with pytest.raises(ValueError, match="image must have shape"):
        backward_warp(np.zeros((2, H, W, 3)), np.zeros((H, W)), (0.0, 1.0))
    with pytest.raises(ValueError, match="offset"):
        backward_warp(np.zeros((H, W)), np.zeros((H, W)), (0.0, 1.0, 2.0))


def test_backward_warp_jit_vmap_over_offsets(key):
    img = jax.random.uniform(key, (H, W, 3))
    d = 0.7 * jax.random.uniform(key, (H, W))
    offs = jnp.array([[0.0, 1.0], [1.0, 0.0], [-2.0, 3.0]])
    batched = jax.jit(jax.vmap(backward_warp, in_axes=(None, None, 0)))(img, d, offs)
    for i in range(3):
        np.testing.assert_allclose(batched[i], backward_warp(img, d, offs[i]), atol=1e-6)


def _channels_last(warp_planar):
    """`backward_warp_planar` with channels-last input and output, for shared tests."""
    return lambda img, d, off: jnp.moveaxis(warp_planar(jnp.moveaxis(img, -1, 0), d, off), 0, -1)


@pytest.mark.parametrize("planar", [False, True], ids=["backward_warp", "backward_warp_planar"])
def test_backward_warp_gradients(x64, key, planar):
    warp = _channels_last(backward_warp_planar) if planar else backward_warp
    k1, k2 = jax.random.split(key)
    img = np.asarray(jax.random.uniform(k1, (8, 9, 2), dtype=jnp.float64))
    # Keep sample positions away from integers and the border, where bilinear is not smooth.
    d = np.asarray(0.3 + 0.2 * jax.random.uniform(k2, (8, 9), dtype=jnp.float64))
    off = np.array([0.5, 1.7])
    check_grads(lambda i, dd: warp(i, dd, off), (img, d), order=1, modes=("rev",), eps=1e-6)
    # The gradient w.r.t. disparity is the image derivative along -(dc, dr).
    ramp = np.tile(np.arange(9, dtype=np.float64) * 2.0, (8, 1))[..., None]  # ∂/∂x = 2
    g = jax.grad(lambda dd: warp(ramp, dd, (0.0, 1.0))[2:6, 3:7].sum())(np.full((8, 9), 0.4))
    np.testing.assert_allclose(np.asarray(g)[2:6, 3:7], -2.0, atol=1e-9)


@pytest.mark.parametrize("shape", [(H, W), (1, W), (H, 1)])
def test_backward_warp_planar_matches_channels_last(key, shape):
    # Same samples as `backward_warp`, border clamping and degenerate 1-px sizes included.
    k1, k2 = jax.random.split(key)
    img = jax.random.uniform(k1, (*shape, 3))
    d = 3.0 * jax.random.normal(k2, shape)  # many samples leave the image: clamped
    for off in [(0.0, 1.0), (-2.0, 0.5), (1.5, -3.0)]:
        planar = backward_warp_planar(jnp.moveaxis(img, -1, 0), d, off)
        assert planar.shape == (3, *shape) and planar.dtype == jnp.float32
        np.testing.assert_allclose(
            jnp.moveaxis(planar, 0, -1), backward_warp(img, d, off), rtol=1e-6, atol=1e-6
        )


def test_backward_warp_planar_bad_shapes_and_vmap(key):
    with pytest.raises(ValueError, match=r"planes must have shape \(C, H, W\)"):
        backward_warp_planar(np.zeros((H, W)), np.zeros((H, W)), (0.0, 1.0))
    with pytest.raises(ValueError, match="spatial shape"):
        backward_warp_planar(np.zeros((3, H, W)), np.zeros((H, W + 1)), (0.0, 1.0))
    with pytest.raises(ValueError, match="offset"):
        backward_warp_planar(np.zeros((3, H, W)), np.zeros((H, W)), (1.0,))
    planes = jax.random.uniform(key, (2, H, W))
    d = 0.7 * jax.random.uniform(key, (H, W))
    offs = jnp.array([[0.0, 1.0], [-2.0, 3.0]])
    batched = jax.jit(jax.vmap(backward_warp_planar, in_axes=(None, None, 0)))(planes, d, offs)
    for i in range(2):
        np.testing.assert_allclose(batched[i], backward_warp_planar(planes, d, offs[i]))


# ---- forward_project -------------------------------------------------------------------------


def test_forward_project_single_point_lands_with_spec_sign():
    d = np.zeros((H, W), np.float32)
    m = np.zeros((H, W), bool)
    d[10, 12], m[10, 12] = 1.5, True
    proj, valid = forward_project(d, (2.0, -1.0), mask=m)
    # lands at (x - dc d, y - dr d) = (12 + 1.5, 10 - 3) → rounded (14 (13.5 rounds up), 7)
    assert np.asarray(valid).sum() == 1
    assert bool(valid[7, 14]) and float(proj[7, 14]) == pytest.approx(1.5)


def test_forward_project_zbuffer_nearer_wins_and_disocclusion_is_a_hole():
    d = np.zeros((H, W), np.float32)
    d[:, 10:16] = 2.0  # near strip
    proj, valid = forward_project(d, (0.0, 1.0))  # near strip moves 2 px left, far stays
    proj, valid = np.asarray(proj), np.asarray(valid)
    np.testing.assert_array_equal(proj[5, 8:14], 2.0)  # near wins where it overlaps the far
    assert not valid[5, 14:16].any()  # disocclusion: 2 px hole, not filled
    assert valid[5, 16] and proj[5, 16] == 0.0
    assert valid[:, W - 1].all()  # far pixels do not move: the right border is covered


def test_forward_project_subpixel_disocclusion_stays_a_hole():
    d = np.zeros((H, W), np.float32)
    d[:, 10:16] = 0.7
    proj, valid = forward_project(d, (0.0, 1.0))
    # near pixels land at round(x - 0.7) = x - 1 → 9..14; far pixel 16 stays; 15 is disoccluded
    assert not np.asarray(valid)[:, 15].any()
    np.testing.assert_allclose(np.asarray(proj)[:, 9:15], 0.7, rtol=1e-6)


def test_forward_project_border_strip_is_a_hole():
    d = np.ones((H, W), np.float32)
    _, valid = forward_project(d, (0.0, 3.0))  # everything moves 3 px left
    valid = np.asarray(valid)
    assert not valid[:, W - 3 :].any() and valid[:, : W - 3].all()


def test_forward_project_fills_cracks_of_a_stretched_slanted_plane():
    ys, xs = _grid(40, 64)
    d = 1.0 - 0.05 * (xs - 32)  # dc = 4 stretches by 1.2 → a crack every ~5 px when rounding
    raw_p, raw_v = forward_project(d, (0.0, 4.0), fill_cracks=False)
    assert (~np.asarray(raw_v)).sum() > 300  # cracks exist without filling
    proj, valid = forward_project(d, (0.0, 4.0))
    assert np.asarray(valid).all()
    # Filled values are the surface's: dest x' sees d = (1 + 0.05*32 - 0.05 x')/(1 + 0.2)
    expect = (1 + 0.05 * 32 - 0.05 * xs) / 1.2
    np.testing.assert_allclose(np.asarray(proj), expect, atol=0.5 * 0.05 / 1.2 + 1e-5)


def test_forward_project_fills_2d_shear_cracks():
    ys, xs = _grid(40, 64)
    d = 0.5 + 0.03 * (xs - 32) - 0.04 * (ys - 20)
    _, raw_v = forward_project(d, (3.0, -4.0), fill_cracks=False)
    assert (~np.asarray(raw_v))[8:-8, 8:-8].sum() > 100
    _, valid = forward_project(d, (3.0, -4.0))
    assert np.asarray(valid)[8:-8, 8:-8].all()


def test_forward_project_no_bleed_through_cracks_of_a_near_surface():
    ys, xs = _grid(20, 64)
    d = np.where((xs > 10) & (xs < 50), 2.0 - 0.06 * (xs - 30), -1.0).astype(np.float32)
    raw, _ = forward_project(d, (0.0, 4.0), fill_cracks=False)
    assert (np.asarray(raw)[:, 6:46] < 0).sum() > 0  # far surface visible through cracks
    proj, _ = forward_project(d, (0.0, 4.0))
    assert (np.asarray(proj)[:, 6:46] < 0).sum() == 0


def test_forward_project_keeps_one_pixel_slits():
    d = np.zeros((H, W), np.float32)
    d[:, 8:24] = 1.0
    d[:, 16] = 0.0  # a slit in the near surface
    proj, valid = forward_project(d, (0.0, 1.0))
    proj, valid = np.asarray(proj), np.asarray(valid)
    # near pixels move 1 px left; the slit column 15 is disoccluded (its far point is hidden
    # in the source): it must stay a hole, not be bridged with the near value
    assert not valid[:, 15].any()
    np.testing.assert_array_equal(proj[:, 7:15], 1.0)
    np.testing.assert_array_equal(proj[:, 16:23], 1.0)


def test_forward_project_mask_and_nonfinite_are_not_projected():
    d = np.ones((H, W), np.float32)
    d[3, 4] = np.nan
    m = np.ones((H, W), bool)
    m[5, 6] = False
    proj, valid = forward_project(d, (0.0, 0.0), mask=m, fill_cracks=False)
    assert not bool(valid[3, 4]) and not bool(valid[5, 6])
    assert np.isfinite(np.asarray(proj)).all()


def test_forward_project_bad_inputs():
    with pytest.raises(ValueError, match=r"\(H, W\)"):
        forward_project(np.zeros((2, H, W)), (0.0, 1.0))
    with pytest.raises(ValueError, match="mask"):
        forward_project(np.zeros((H, W)), (0.0, 1.0), mask=np.ones((H, W + 1), bool))
    with pytest.raises(ValueError, match="offset"):
        forward_project(np.zeros((H, W)), 1.0)
    with pytest.raises(ValueError, match="crack_parallax"):
        forward_project(np.zeros((H, W)), (0.0, 1.0), crack_parallax=-1.0)


def test_forward_project_jit_vmap_and_gradient_reaches_winners(key):
    d = 0.5 + 0.5 * jax.random.uniform(key, (H, W))
    offs = jnp.array([[0.0, 1.0], [1.0, 0.0], [-2.0, 3.0]])
    P, Vd = jax.jit(jax.vmap(forward_project, in_axes=(None, 0)))(d, offs)
    for i in range(3):
        p, v = forward_project(d, offs[i])
        np.testing.assert_array_equal(P[i], p)
        np.testing.assert_array_equal(Vd[i], v)
    # The output values are gathered from the input: d(sum proj)/dd counts landings.
    g = jax.grad(lambda dd: forward_project(dd, jnp.array([0.0, 0.0]))[0].sum())(d)
    np.testing.assert_allclose(g, 1.0)


def test_forward_project_traced_crack_parallax():
    ys, xs = _grid(40, 64)
    d = 1.0 - 0.05 * (xs - 32)
    f = jax.jit(lambda t: forward_project(d, (0.0, 4.0), crack_parallax=t)[1].sum())
    assert int(f(0.5)) == 40 * 64  # all cracks filled
    assert int(f(0.0)) < 40 * 64 - 300  # threshold 0: nothing is continuous enough


@pytest.mark.parametrize("fill_cracks", [True, False])
def test_forward_project_views_is_each_projection(key, fill_cracks):
    """The stacked projection equals `forward_project` of every map alone, bit for bit: per
    map (with its mask) and one shared map into several views, slanted surfaces, depth steps
    and pixels leaving the frame included."""
    k1, k2, k3 = jax.random.split(key, 3)
    ys, xs = _grid()
    plane = 0.4 + 0.06 * (jnp.asarray(xs) - W / 2)
    step = jnp.where(jnp.asarray(xs) > W / 2, 1.5, -0.5)
    noise = jax.random.uniform(k1, (H, W), minval=-1.0, maxval=1.0)
    maps = jnp.stack([plane, step, noise, plane + step])
    offsets = jnp.array([[0.0, 2.0], [-1.0, 0.0], [1.0, -2.0], [2.0, 1.0]])
    mask = jax.random.uniform(k2, maps.shape) > 0.1
    p, v = jax.jit(functools.partial(forward_project_views, fill_cracks=fill_cracks))(
        maps, offsets, mask=mask
    )
    for i in range(4):
        pi, vi = forward_project(maps[i], offsets[i], mask=mask[i], fill_cracks=fill_cracks)
        np.testing.assert_array_equal(p[i], pi)
        np.testing.assert_array_equal(v[i], vi)
    assert int(jnp.sum(~v)) > 0 and int(jnp.sum(v)) > 0
    shared = jax.random.uniform(k3, (H, W), minval=-1.5, maxval=1.5)
    p, v = forward_project_views(shared, offsets, fill_cracks=fill_cracks, crack_parallax=0.7)
    for i in range(4):
        pi, vi = forward_project(shared, offsets[i], fill_cracks=fill_cracks, crack_parallax=0.7)
        np.testing.assert_array_equal(p[i], pi)
        np.testing.assert_array_equal(v[i], vi)


def test_forward_project_views_bad_inputs():
    with pytest.raises(ValueError, match=r"\(K, 2\)"):
        forward_project_views(np.zeros((H, W)), np.zeros((3,)))
    with pytest.raises(ValueError, match=r"\(3, H, W\)"):
        forward_project_views(np.zeros((2, H, W)), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="mask"):
        forward_project_views(np.zeros((3, H, W)), np.zeros((3, 2)), mask=np.ones((2, H, W), bool))
    with pytest.raises(ValueError, match="crack_parallax"):
        forward_project_views(np.zeros((H, W)), np.zeros((3, 2)), crack_parallax=-0.5)


@pytest.mark.parametrize(
    "case, platform, fill_cracks, warns",
    [
        (0, "gpu", True, True),
        (1, "cuda", True, True),
        (2, "gpu", False, False),
        (3, "cpu", True, False),
    ],
)
def test_crack_fill_compiled_for_a_gpu_warns(monkeypatch, case, platform, fill_cracks, warns):
    # The warning is raised when the crack fill is traced for a GPU (a shape of its own per
    # case, which no other test compiles, so that the projection is traced here).
    monkeypatch.setattr(_warp, "_default_platform", lambda: platform)
    d = jnp.zeros((3, 7, 11 + case), jnp.float32).at[:, 3, 5].set(1.0)
    offsets = jnp.asarray([[0.0, 1.0], [1.0, 0.0], [1.0, 1.0]])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        forward_project_views(d, offsets, fill_cracks=fill_cracks)
    got = [w for w in caught if issubclass(w.category, GpuCompileWarning)]
    assert bool(got) == warns, [str(w.message) for w in caught]
    if warns:
        assert "wrong code" in str(got[0].message)


def test_default_platform_follows_the_default_device():
    assert _warp._default_platform() == jax.default_backend()
    with jax.default_device(jax.devices("cpu")[0]):
        assert _warp._default_platform() == "cpu"
