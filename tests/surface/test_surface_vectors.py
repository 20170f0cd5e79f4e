"""Surface vectors by bidirectional diffusion (thesis Ch. 4.2–4.3)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads
from scipy.ndimage import maximum_filter, minimum_filter

from mvedge_jax.edges import EdgeSet
from mvedge_jax.lightfield import rgb_to_lab
from mvedge_jax.surface import SurfaceConfig, splat_labels, step_responses, surface_vectors
from mvedge_jax.synthetic import make_scene


def gt_edge_set(centre: np.ndarray, gt: np.ndarray, threshold: float = 0.08) -> EdgeSet:
    """Edge points at strong colour edges of the centre view, labelled with the GT disparity."""
    lab = np.asarray(rgb_to_lab(centre)) / 100.0
    gx = np.zeros(lab.shape[:2])
    gy = np.zeros(lab.shape[:2])
    gx[:, 1:-1] = np.linalg.norm(lab[:, 2:] - lab[:, :-2], axis=-1) / 2
    gy[1:-1] = np.linalg.norm(lab[2:] - lab[:-2], axis=-1) / 2
    ys, xs = np.nonzero(np.hypot(gx, gy) > threshold)
    n = xs.size
    es = EdgeSet.empty(n)
    return EdgeSet(
        x=jnp.asarray(xs, jnp.float32),
        y=jnp.asarray(ys, jnp.float32),
        disparity=jnp.asarray(gt[ys, xs], jnp.float32),
        confidence=jnp.ones(n),
        visible=jnp.ones(n, bool),
        lab=es.lab,
        direction=es.direction,
        intercepts=es.intercepts,
        valid=jnp.ones(n, bool),
        n_dropped=es.n_dropped,
    )


def true_sides(es: EdgeSet, normal: np.ndarray, gt: np.ndarray):
    """(+1/-1 side whose GT is nearer the label, depth-edge mask) per point."""
    H, W = gt.shape
    x, y, d = np.asarray(es.x), np.asarray(es.y), np.asarray(es.disparity)

    def at(sign):
        px = np.clip(np.round(x + sign * 2 * normal[:, 0]).astype(int), 0, W - 1)
        py = np.clip(np.round(y + sign * 2 * normal[:, 1]).astype(int), 0, H - 1)
        return gt[py, px]

    span = (maximum_filter(gt, 3) - minimum_filter(gt, 3))[y.astype(int), x.astype(int)]
    return np.where(np.abs(at(1) - d) <= np.abs(at(-1) - d), 1.0, -1.0), span > 0.2


@pytest.fixture(scope="module")
def scene():
    lf = make_scene(3, grid=(3, 3), size=(96, 96))
    return np.asarray(lf.centre_view), np.asarray(lf.centre_gt)


def test_sides_on_synthetic_depth_edges(scene):
    centre, gt = scene
    es = gt_edge_set(centre, gt)
    res = jax.jit(surface_vectors)(es, jnp.asarray(centre), SurfaceConfig())
    truth, depth = true_sides(es, np.asarray(res.normal), gt)
    chosen = np.sign(np.sum(np.asarray(res.offset) * np.asarray(res.normal), axis=1))
    assert depth.sum() > 100
    acc = np.mean(chosen[depth] == truth[depth])
    assert acc >= 0.95, acc
    # λ_e separates depth edges from texture edges: depth-edge points respond far more.
    lam = np.asarray(res.step_response)
    span_small = ~depth
    assert np.median(lam[depth]) > 5 * np.median(lam[span_small])
    assert float(res.residual.max()) < 1e-4


@pytest.mark.parametrize("edge_label, expected_dx", [(1.0, 1.0), (-1.0, -1.0)])
def test_plane_over_plane_points_to_the_labelled_surface(edge_label, expected_dx):
    H, W = 32, 32
    img = np.full((H, W, 3), 0.2, np.float32)
    img[:, 16:] = 0.8  # colour (and depth) edge between x = 15 and x = 16
    ys = np.arange(4, 28, dtype=np.float32)
    # Interior labels: left surface d = -1 (x = 5), right surface d = +1 (x = 26); the edge
    # points at x = 15.5 carry the label of one of the two surfaces.
    x = np.concatenate([np.full_like(ys, 15.5), np.full_like(ys, 5.0), np.full_like(ys, 26.0)])
    y = np.concatenate([ys, ys, ys])
    d = np.concatenate([np.full(24, edge_label), np.full(24, -1.0), np.full(24, 1.0)])
    es0 = EdgeSet.empty(72)
    es = EdgeSet(
        x=jnp.asarray(x),
        y=jnp.asarray(y),
        disparity=jnp.asarray(d, jnp.float32),
        confidence=jnp.ones(72),
        visible=jnp.ones(72, bool),
        lab=es0.lab,
        direction=es0.direction,
        intercepts=es0.intercepts,
        valid=jnp.ones(72, bool),
        n_dropped=es0.n_dropped,
    )
    res = surface_vectors(es, jnp.asarray(img), SurfaceConfig(gradient_sigma=1.0))
    off = np.asarray(res.offset)[:24]
    assert np.all(off[:, 0] * expected_dx > 0.9), off[:, 0]


def test_invalid_points_get_zero_offset_and_shapes(scene):
    centre, gt = scene
    es = gt_edge_set(centre, gt)
    es = EdgeSet(**{**es.__dict__, "valid": es.valid.at[::2].set(False)})
    res = surface_vectors(es, jnp.asarray(centre))
    N = es.capacity
    assert res.offset.shape == (N, 2) and res.step_response.shape == (N,)
    assert res.depth_edge_confidence.shape == gt.shape
    assert np.all(np.asarray(res.offset)[::2] == 0) and np.all(
        np.asarray(res.step_response)[::2] == 0
    )
    c = np.asarray(res.depth_edge_confidence)
    assert c.min() >= 0 and c.max() <= 1


def test_bad_input():
    es = EdgeSet.empty(4)
    with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
        surface_vectors(es, jnp.zeros((8, 8)))
    with pytest.raises(ValueError, match="offset"):
        SurfaceConfig(offset=0.0)


def test_splat_conserves_weight_and_mean():
    x = jnp.array([3.3, 7.9, 0.0])
    y = jnp.array([2.6, 5.1, 0.0])
    v = jnp.array([1.0, 2.0, 3.0])
    w = jnp.array([1.0, 0.5, 0.0])
    label, weight = splat_labels(x, y, v, w, (10, 10))
    assert float(weight.sum()) == pytest.approx(1.5, abs=1e-5)
    assert float(label[2, 3]) == pytest.approx(1.0, abs=1e-5)


def test_step_response_of_unit_step():
    d = jnp.tile((jnp.arange(20) >= 10).astype(jnp.float32), (20, 1))
    r = step_responses(d, jnp.array([9.5]), jnp.array([10.0]), jnp.array([[1.0, 0.0]]))
    assert float(r[0]) == pytest.approx(1.0, abs=1e-5)


def test_gradient_of_lambda_e_wrt_labels(x64):
    H = W = 12
    img = np.full((H, W, 3), 0.2)
    img[:, 6:] = 0.9
    y = jnp.arange(2.0, 10.0)
    x = jnp.full_like(y, 5.5)
    es0 = EdgeSet.empty(8)
    cfg = SurfaceConfig(gradient_sigma=1.0)

    def f(d):
        es = EdgeSet(
            x=x,
            y=y,
            disparity=d,
            confidence=jnp.ones(8),
            visible=jnp.ones(8, bool),
            lab=es0.lab,
            direction=es0.direction,
            intercepts=es0.intercepts,
            valid=jnp.ones(8, bool),
            n_dropped=es0.n_dropped,
        )
        return surface_vectors(es, jnp.asarray(img), cfg).step_response.sum()

    d0 = jnp.linspace(0.5, 1.0, 8)
    check_grads(jax.jit(f), (d0,), order=1, modes=("rev",), eps=1e-6, atol=1e-4, rtol=1e-3)


def test_side_score_prefers_label_consistent_step():
    # Oriented profiles at t = -3..-1, 1..3 (label side t > 0), label d = 1.
    good = jnp.array([[0.0, 0.0, 0.0, 1.0, 1.0, 1.0]])  # flat at the label, step to 0
    smeared = jnp.array([[1.0, 1.0, 1.0, 0.9, 0.6, 0.3]])  # label pushed across the edge
    label = jnp.array([1.0])
    from mvedge_jax.surface import side_score

    assert float(side_score(good, label)[0]) == pytest.approx(1.0, abs=1e-6)
    assert float(side_score(smeared, label)[0]) < 0.0


def test_thesis_data_weight_converges(scene):
    centre, gt = scene
    es = gt_edge_set(centre, gt)
    res = surface_vectors(es, jnp.asarray(centre), SurfaceConfig(data_weight=1e6))
    assert float(res.residual.max()) <= 1e-5
    truth, depth = true_sides(es, np.asarray(res.normal), gt)
    chosen = np.sign(np.sum(np.asarray(res.offset) * np.asarray(res.normal), axis=1))
    assert np.mean(chosen[depth] == truth[depth]) >= 0.9
