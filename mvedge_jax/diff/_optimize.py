"""Block-coordinate Adam over Θ̄ = {Z, positions, R, Q} (thesis Sec. 7.1.4–7.1.5)."""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
from jaxtyping import Array, ArrayLike, Bool, Float

from .._fields import check_fields, hyperparameter_vector, static
from ..edges import EdgeSet
from ._loss import LossConfig, self_supervised_loss, supervised_loss
from ._model import DiffParams, ModelConfig, initial_params, predict, sample_bilinear

BLOCKS = ("label", "position", "R", "Q")

_DEFAULT_MODEL = ModelConfig()


class OptimizeConfig(eqx.Module):
    """Schedule of the block-coordinate optimisation.

    Every pass ``k`` optimises each block of ``blocks`` in turn for ``iterations`` Adam steps
    with learning rate ``learning_rate[b] * decay[b] ** k`` (a fresh Adam state per turn),
    ``b`` indexing `BLOCKS` = ``("label", "position", "R", "Q")``.

    Attributes:
        model: `ModelConfig` (rendering, diffusion weights, solver).
        loss: `LossConfig`.
        blocks: order of the blocks within a pass (names from `BLOCKS`).
        iterations: Adam steps per block and pass (thesis: 13; the authors' code: 25).
        passes: passes over the blocks (thesis: 5).
        learning_rate: ``(4,)`` initial learning rates of label Z, position, R, Q (authors'
            code: 0.015, 0.1, 0.015, 0.015; positions in pixels).
        decay: ``(4,)`` per-pass decay factors (authors' code: 0.9, 0.75, 0.8, 0.9).
    """

    model: ModelConfig = ModelConfig()
    loss: LossConfig = LossConfig()
    blocks: tuple[str, ...] = eqx.field(static=True, default=BLOCKS)
    iterations: int = static(13, lower=0, upper=100_000)
    passes: int = static(5, lower=0, upper=1000)
    learning_rate: Array = hyperparameter_vector(
        (0.015, 0.1, 0.015, 0.015), differentiable=True, lower=0.0
    )
    decay: Array = hyperparameter_vector((0.9, 0.75, 0.8, 0.9), differentiable=True, lower=0.0)

    def __check_init__(self):
        check_fields(self)
        bad = [b for b in self.blocks if b not in BLOCKS]
        if bad or not self.blocks:
            raise ValueError(
                f"OptimizeConfig.blocks must be names from {BLOCKS}; got {self.blocks}"
            )

    def schedule(self) -> list[tuple[int, str, Array]]:
        """``[(pass, block, learning_rate), ...]`` in execution order."""
        out = []
        for k in range(self.passes):
            for b in self.blocks:
                i = BLOCKS.index(b)
                out.append((k, b, self.learning_rate[i] * self.decay[i] ** k))
        return out


_DEFAULT_OPTIMIZE = OptimizeConfig()


class Data(eqx.Module):
    """What the loss compares against (any of the fields may be ``None``), and the prior map
    of the diffusion (`predict`'s ``prior``)."""

    centre: Float[Array, "H W 3"] | None
    others: Float[Array, "K H W 3"] | None
    offsets: Float[Array, "K 2"] | None
    target: Float[Array, "H W"] | None
    target_mask: Bool[Array, "H W"] | None
    prior: Float[Array, "H W"] | None = None


def objective(disparity: Array, data: Data, config: LossConfig) -> Array:
    """Total loss: supervised L1 (if a target is given) + eq 7.16 (if other views are given)."""
    total = jnp.zeros((), disparity.dtype)
    if data.target is not None:
        total = total + config.supervised * supervised_loss(
            disparity, data.target, data.target_mask
        )
    if data.others is not None:
        total = total + self_supervised_loss(
            disparity, data.centre, data.others, data.offsets, config
        )
    return total


_adam = optax.scale_by_adam()


@eqx.filter_jit
def _step(params: DiffParams, states, block, lr, x0, valid, data: Data, config: OptimizeConfig):
    """One Adam step on the block ``BLOCKS[block]`` (``block`` is a traced int: one compile;
    ``-1`` updates nothing and just evaluates).

    The gradient of every block is computed (one backward pass through solve and render);
    only the active block and its Adam state change.
    """

    def loss_fn(p):
        pred = predict(p, config.model, valid=valid, x0=x0, prior=data.prior)
        return objective(pred.disparity, data, config.loss), pred

    (loss, pred), grads = jax.value_and_grad(loss_fn, has_aux=True)(params)
    new_params, new_states = adam_block_update(params, grads, states, block, lr, jnp.isfinite(loss))
    mse = jnp.zeros((), pred.disparity.dtype)
    if data.target is not None:
        err = (pred.disparity - data.target) ** 2
        if data.target_mask is not None:
            m = data.target_mask.astype(err.dtype)
            mse = 100.0 * jnp.sum(err * m) / jnp.maximum(jnp.sum(m), 1.0)
        else:
            mse = 100.0 * jnp.mean(err)
    info = {
        "loss": loss,
        "mse_x100": mse,
        "solver_iterations": pred.solve.iterations,
        "solver_residual": pred.solve.residual,
        "overflow": pred.rendered.overflow,
    }
    return new_params, new_states, pred.disparity, info


def adam_reset(params: DiffParams, states=None, block: str | None = None):
    """Fresh Adam states: for every block (``states`` None), or for ``block`` alone (the
    others kept), as at the start of each turn of the schedule."""
    if states is None:
        return tuple(_adam.init(getattr(params, name)) for name in BLOCKS)
    return tuple(
        _adam.init(getattr(params, name)) if name == block else st
        for name, st in zip(BLOCKS, states, strict=True)
    )


def adam_block_update(params: DiffParams, grads: DiffParams, states, block, lr, ok):
    """Adam on the block ``BLOCKS[block]`` alone (traced ``block``; ``-1`` changes nothing).

    Every block's Adam state sees its gradient (non-finite entries zeroed), but only the
    active block's parameters and state change, and nothing changes where ``ok`` is False
    (a non-finite loss). Returns ``(params, states)`` with ``states`` a tuple per block.
    """
    new_params, new_states = params, []
    for i, name in enumerate(BLOCKS):
        sub, g = getattr(params, name), getattr(grads, name)
        g = jnp.where(jnp.isfinite(g), g, 0.0)
        upd, st = _adam.update(g, states[i])
        active = ok & (block == i)
        new_sub = jnp.where(active, sub - lr.astype(sub.dtype) * upd, sub)
        new_params = eqx.tree_at(lambda q, n=name: getattr(q, n), new_params, new_sub)
        new_states.append(
            jax.tree.map(lambda a, b, act=active: jnp.where(act, a, b), st, states[i])
        )
    return new_params, tuple(new_states)


def params_from_edges(
    edges: EdgeSet,
    centre_view: Float[ArrayLike, "H W 3"],
    config: ModelConfig = _DEFAULT_MODEL,
    *,
    disparity: Float[ArrayLike, "H W"] | None = None,
) -> tuple[DiffParams, Bool[Array, " N"]]:
    """Starting parameters from a multi-view edge set (Ch. 4 points, optionally Ch. 6 labels).

    Args:
        edges: `EdgeSet` of capacity N (positions in centre-view pixels).
        centre_view: ``(H, W, 3)`` centre view in [0, 1] (grid and Q initialisation).
        config: `ModelConfig` (``q_scale``).
        disparity: optional ``(H, W)`` dense disparity (e.g. the Ch. 6 reconstruction); when
            given, each point's label is that map sampled (bilinearly) at the point instead
            of the edge's own disparity.

    Returns:
        ``(params, valid)``: `DiffParams` and the ``(N,)`` validity mask of the points.
    """
    pos = jnp.stack([edges.x, edges.y], axis=1)
    label = edges.disparity
    if disparity is not None:
        label = sample_bilinear(jnp.asarray(disparity, jnp.float32), pos)
    label = jnp.where(edges.valid, label, 0.0)
    pos = jnp.where(edges.valid[:, None], pos, 0.0)
    return initial_params(pos, label, centre_view, config), edges.valid


def optimize(
    points: DiffParams | EdgeSet,
    centre_view: Float[ArrayLike, "H W 3"],
    other_views: Float[ArrayLike, "K H W 3"] | None,
    offsets: Float[ArrayLike, "K 2"] | None,
    config: OptimizeConfig = _DEFAULT_OPTIMIZE,
    *,
    target_disparity: Float[ArrayLike, "H W"] | None = None,
    target_mask: Bool[ArrayLike, "H W"] | None = None,
    valid: Bool[ArrayLike, " N"] | None = None,
    prior: Float[ArrayLike, "H W"] | None = None,
    callback: Callable[[int, dict], None] | None = None,
) -> tuple[DiffParams, dict[str, np.ndarray]]:
    """Optimise the point set and smoothness by block-coordinate Adam (thesis Sec. 7.1.5).

    The loss is the self-supervised eq 7.16 when ``other_views`` are given, plus the
    supervised L1 of Sec. 7.2.3 when ``target_disparity`` is given (at least one is
    required). One jitted step function (specialised per block) is called
    ``passes × len(blocks) × iterations`` times (the active block is a traced index, so it
    compiles once); the solve is warm-started from the previous disparity.

    Args:
        points: initial `DiffParams` (see `initial_params`) or an `EdgeSet` (converted with
            `params_from_edges`; its ``valid`` mask is used).
        centre_view: ``(H, W, 3)`` reference view in [0, 1].
        other_views: ``(K, H, W, 3)`` other views, or ``None`` (supervised only).
        offsets: ``(K, 2)`` ``(dr, dc)`` of the other views from the reference view.
        config: `OptimizeConfig`.
        target_disparity: ``(H, W)`` disparity for the supervised loss, or ``None``.
        target_mask: ``(H, W)`` bool pixels of the target to use (default all).
        valid: ``(N,)`` bool point mask (default: the EdgeSet's, or all).
        prior: optional ``(H, W)`` disparity map whose departures the points encode
            (`predict`'s ``prior``; e.g. the Ch. 6 map being refined); also the first warm
            start of the solve.
        callback: called as ``callback(step, info)`` after every step (progress bars).

    Returns:
        ``(params, history)``: the optimised `DiffParams`; ``history`` holds per-step NumPy
        arrays ``loss``, ``mse_x100`` (0 without a target), ``pass``, ``block`` (index into
        `BLOCKS`), ``solver_iterations``, ``solver_residual``, ``overflow``, ``seconds``, and
        ``disparity``, the final ``(H, W)`` diffused map.

    Raises:
        ValueError: on missing data or mismatched shapes.

    References:
        Thesis Sec. 7.1.4–7.1.5 (Adam, one parameter block at a time, 13 iterations × 5
        passes), Sec. 7.2.3 (supervised loss).
    """
    centre = jnp.asarray(centre_view, jnp.float32)
    if centre.ndim != 3 or centre.shape[-1] != 3:
        raise ValueError(f"centre_view must have shape (H, W, 3); got {tuple(centre.shape)}")
    if isinstance(points, EdgeSet):
        params, edge_valid = params_from_edges(points, centre, config.model)
        valid = edge_valid if valid is None else jnp.asarray(valid, bool) & edge_valid
    elif isinstance(points, DiffParams):
        params = points
    else:
        raise ValueError(f"points must be DiffParams or EdgeSet; got {type(points).__name__}")
    H, W = centre.shape[:2]
    if params.shape != (H, W):
        raise ValueError(f"params.Q has shape {params.shape}; the centre view is {(H, W)}")
    if other_views is None and target_disparity is None:
        raise ValueError("give other_views (self-supervised) and/or target_disparity (supervised)")
    others = offs = None
    if other_views is not None:
        others = jnp.asarray(other_views, jnp.float32)
        if offsets is None:
            raise ValueError("offsets are required with other_views")
        offs = jnp.asarray(offsets, jnp.float32)
        if others.ndim != 4 or others.shape[1:] != (H, W, 3):
            raise ValueError(f"other_views must have shape (K, {H}, {W}, 3); got {others.shape}")
        if offs.shape != (others.shape[0], 2):
            raise ValueError(f"offsets must have shape ({others.shape[0]}, 2); got {offs.shape}")
    target = tmask = None
    if target_disparity is not None:
        target = jnp.asarray(target_disparity, params.label.dtype)
        if target.shape != (H, W):
            raise ValueError(f"target_disparity must have shape {(H, W)}; got {target.shape}")
        if target_mask is not None:
            tmask = jnp.asarray(target_mask, bool)
            if tmask.shape != (H, W):
                raise ValueError(f"target_mask must have shape {(H, W)}; got {tmask.shape}")
    if prior is not None:  # its shape is checked by `predict`
        prior = jnp.asarray(prior, params.label.dtype)
    data = Data(
        centre=centre, others=others, offsets=offs, target=target, target_mask=tmask, prior=prior
    )
    if valid is not None:
        valid = jnp.asarray(valid, bool)
        if valid.shape != params.label.shape:
            raise ValueError(f"valid must have shape {params.label.shape}; got {valid.shape}")

    x0 = jnp.zeros((H, W), params.label.dtype) if prior is None else prior
    hist: dict[str, list] = {
        k: []
        for k in (
            "loss",
            "mse_x100",
            "pass",
            "block",
            "solver_iterations",
            "solver_residual",
            "overflow",
            "seconds",
        )
    }
    step = 0
    states = adam_reset(params)
    for k, block, lr in config.schedule():
        b = BLOCKS.index(block)
        # a fresh Adam state for every block turn
        states = adam_reset(params, states, block)
        bi = jnp.asarray(b, jnp.int32)
        for _ in range(config.iterations):
            t0 = time.perf_counter()
            params, states, x0, info = _step(params, states, bi, lr, x0, valid, data, config)
            info = {name: float(v) for name, v in info.items()}
            info["seconds"] = time.perf_counter() - t0
            info["pass"], info["block"] = k, BLOCKS.index(block)
            for name in hist:
                hist[name].append(info[name])
            if callback is not None:
                callback(step, info)
            step += 1
    history = {name: np.asarray(v) for name, v in hist.items()}
    if history["overflow"].size and history["overflow"].max() > 0:
        warnings.warn(
            f"up to {int(history['overflow'].max())} points did not fit their screen tiles and "
            "were dropped from some pixels; raise RenderConfig.tile_levels",
            RuntimeWarning,
            stacklevel=2,
        )
    # the final map: one more call of the same compiled step with no active block
    none = jnp.asarray(-1, jnp.int32)
    _, _, final, _ = _step(params, states, none, jnp.zeros(()), x0, valid, data, config)
    history["disparity"] = np.asarray(final)
    return params, history
