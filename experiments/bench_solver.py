"""Benchmark `solve_poisson`: preconditioners × problem sizes, forward and forward+backward.

Problems (float32), built from the backgammon centre view and its GT disparity when the shared
data is present (synthetic blocks otherwise):

* ``512x512``: sparse-to-dense diffusion as in thesis eq 6.1: data weight 150 on the 8 % of
  pixels with the strongest image gradient (target: GT disparity there), smoothness
  ``1 / (|∇I| + 0.01)`` from the centre view.
* ``1024x1024``: the same on the 2× upsampled scene.
* ``512x(9x512)``: 512 horizontal EPIs of 9×512 (vmapped), angular inpainting as in eq 6.4:
  data weight 15 on 70 % of the EPI pixels (random "reprojected" pixels), target = the GT
  disparity of that row, smoothness ``0.1 / (|∇E| + 0.01)`` from the EPI.

Reference: ``scipy.sparse.linalg.spsolve`` in float64 (OPENBLAS_NUM_THREADS=1); skipped above
``--direct-max-unknowns`` unknowns (then ``rel_error_vs_direct`` is null and
``rel_error_vs_f64_pcg`` compares against our own float64 multigrid PCG at rtol 1e-12). For
the EPI batch the direct reference is computed for ``--direct-epis`` EPIs only.

Usage:
    OPENBLAS_NUM_THREADS=1 python experiments/bench_solver.py --json OUT.json [--repeats 5]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import json  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import click  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
import scipy.sparse.linalg as spla  # noqa: E402

from mvedge_jax.solve import SolverConfig, guide_edge_weights, solve_poisson  # noqa: E402

DATA = Path(os.environ.get("MVEDGE_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))


def _scene() -> tuple[np.ndarray, np.ndarray, str]:
    """``(views (9, 9, H, W, 3), centre GT (H, W), name)``."""
    folder = DATA / "hci4d" / "stratified" / "backgammon"
    if folder.is_dir():
        from mvedge_jax.io import read_hci4d

        lf = read_hci4d(folder)
        return np.asarray(lf.views), np.asarray(lf.centre_gt), "backgammon"
    rng = np.random.default_rng(0)
    views = rng.uniform(size=(9, 9, 32, 32, 3)).repeat(16, 2).repeat(16, 3).astype(np.float32)
    gt = rng.uniform(-1, 1, (32, 32)).repeat(16, 0).repeat(16, 1).astype(np.float32)
    return views, gt, "synthetic-blocks"


def _image_problem(image: np.ndarray, gt: np.ndarray):
    gy, gx = np.gradient(image, axis=(0, 1))
    g = np.linalg.norm(gx, axis=-1) + np.linalg.norm(gy, axis=-1)
    lam = np.where(g >= np.quantile(g, 0.92), 150.0, 0.0).astype(np.float32)
    wx, wy = guide_edge_weights(jnp.asarray(image), scale=1.0, eps=0.01)
    return lam, gt.astype(np.float32), np.asarray(wx), np.asarray(wy)


def _epi_problems(views: np.ndarray, gt: np.ndarray, rng):
    V = views.shape[1]
    epis = np.transpose(views[views.shape[0] // 2], (1, 0, 2, 3))  # (H, V, W, 3)
    H, _, W, _ = epis.shape
    lam = np.where(rng.uniform(size=(H, V, W)) < 0.7, 15.0, 0.0).astype(np.float32)
    S = np.broadcast_to(gt[:, None, :], (H, V, W)).astype(np.float32)
    wx, wy = jax.vmap(lambda e: guide_edge_weights(e, scale=0.1, eps=0.01))(jnp.asarray(epis))
    return lam, S, np.asarray(wx), np.asarray(wy)


def _sparse_matrix(lam, wx, wy) -> sp.csr_matrix:
    H, W = lam.shape
    idx = np.arange(H * W).reshape(H, W)
    rows = [idx[:, :-1].ravel(), idx[:-1, :].ravel()]
    cols = [idx[:, 1:].ravel(), idx[1:, :].ravel()]
    vals = [wx.ravel().astype(np.float64), wy.ravel().astype(np.float64)]
    i = np.concatenate(rows + cols)
    j = np.concatenate(cols + rows)
    v = -np.concatenate(vals + vals)
    L = sp.coo_matrix((v, (i, j)), shape=(H * W, H * W)).tocsr()
    d = -np.asarray(L.sum(axis=1)).ravel() + lam.ravel().astype(np.float64)
    return (L + sp.diags(d)).tocsc()


def _direct(lam, S, wx, wy) -> tuple[np.ndarray, float]:
    A = _sparse_matrix(lam, wx, wy)
    b = lam.ravel().astype(np.float64) * S.ravel().astype(np.float64)
    t = time.perf_counter()
    x = spla.spsolve(A, b)
    return x.reshape(lam.shape), time.perf_counter() - t


def _f64_reference(lam, S, wx, wy) -> np.ndarray:
    jax.config.update("jax_enable_x64", True)
    try:
        args = [jnp.asarray(a, jnp.float64) for a in (lam, S, wx, wy)]
        cfg = SolverConfig(preconditioner="multigrid", rtol=1e-12, max_iters=2000)
        return np.asarray(solve_poisson(*args, config=cfg).x)
    finally:
        jax.config.update("jax_enable_x64", False)


def _median_ms(f, args, repeats: int) -> float:
    jax.block_until_ready(f(*args))  # compile
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(f(*args))
        times.append(time.perf_counter() - t)
    return 1000.0 * statistics.median(times)


def _rel(x, ref) -> float:
    return float(np.linalg.norm(np.asarray(x, np.float64) - ref) / np.linalg.norm(ref))


@click.command()
@click.option("--json", "json_out", type=click.Path(dir_okay=False), required=True)
@click.option("--repeats", default=5, show_default=True)
@click.option("--rtol", default=1e-5, show_default=True)
@click.option("--direct-max-unknowns", default=512 * 512, show_default=True)
@click.option("--direct-epis", default=16, show_default=True)
@click.option("--sizes", default="512,1024,epi", show_default=True)
@click.option("--preconditioners", default="none,jacobi,multigrid", show_default=True)
def main(json_out, repeats, rtol, direct_max_unknowns, direct_epis, sizes, preconditioners):
    """Write a list of {size, preconditioner, iterations, forward_ms, forward_backward_ms,
    rel_error_vs_direct, ...} to JSON_OUT and print a table."""
    views, gt, name = _scene()
    centre = views[views.shape[0] // 2, views.shape[1] // 2]
    rng = np.random.default_rng(0)
    problems = {}
    for s in sizes.split(","):
        if s == "512":
            problems["512x512"] = _image_problem(centre, gt)
        elif s == "1024":
            up = centre.repeat(2, 0).repeat(2, 1)
            problems["1024x1024"] = _image_problem(up, gt.repeat(2, 0).repeat(2, 1))
        elif s == "epi":
            problems["512x(9x512)"] = _epi_problems(views, gt, rng)
        else:
            raise click.BadParameter(f"unknown size {s!r}")
    rows = []
    for size, (lam, S, wx, wy) in problems.items():
        batched = lam.ndim == 3
        n = lam[0].size if batched else lam.size
        ref, ref_kind, direct_s = None, None, None
        if n <= direct_max_unknowns:
            if batched:
                k = min(direct_epis, lam.shape[0])
                sols = [_direct(lam[i], S[i], wx[i], wy[i]) for i in range(k)]
                ref = np.stack([s[0] for s in sols])
                direct_s = sum(s[1] for s in sols) / k
                ref_kind = f"spsolve float64 on the first {k} EPIs"
            else:
                ref, direct_s = _direct(lam, S, wx, wy)
                ref_kind = "spsolve float64"
        else:
            ref = _f64_reference(lam, S, wx, wy)
            ref_kind = f"spsolve skipped ({n} unknowns); float64 multigrid PCG rtol 1e-12"
        probe = jnp.asarray(np.random.default_rng(1).normal(size=lam.shape).astype(np.float32))
        args = tuple(jnp.asarray(a) for a in (lam, S, wx, wy))
        for p in preconditioners.split(","):
            cfg = SolverConfig(preconditioner=p, rtol=rtol, max_iters=5000)
            fwd = jax.jit(lambda *a, cfg=cfg: solve_poisson(*a, config=cfg))
            loss = lambda *a, cfg=cfg, probe=probe: jnp.sum(probe * solve_poisson(*a, config=cfg).x)
            fb = jax.jit(jax.value_and_grad(loss, argnums=(0, 1, 2, 3)))
            out = fwd(*args)
            x = np.asarray(out.x)
            xr = x[: ref.shape[0]] if batched else x
            rel = _rel(xr, ref)
            row = {
                "size": size,
                "preconditioner": p,
                "iterations": int(np.max(out.iterations)),
                "iterations_mean": float(np.mean(out.iterations)),
                "residual": float(np.max(out.residual)),
                "forward_ms": _median_ms(fwd, args, repeats),
                "forward_backward_ms": _median_ms(fb, args, repeats),
                "rel_error_vs_direct": rel if ref_kind.startswith("spsolve float64") else None,
                "reference": ref_kind,
                "direct_s": direct_s,
                "scene": name,
                "rtol": rtol,
            }
            if not ref_kind.startswith("spsolve float64"):
                row["rel_error_vs_f64_pcg"] = rel
            rows.append(row)
            print(
                f"{size:>12} {p:>9}  it {row['iterations']:5d}  res {row['residual']:.1e}  "
                f"fwd {row['forward_ms']:9.1f} ms  fwd+bwd {row['forward_backward_ms']:9.1f} ms"
                f"  rel.err {rel:.1e}  ({ref_kind})",
                flush=True,
            )
    Path(json_out).parent.mkdir(parents=True, exist_ok=True)
    Path(json_out).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
