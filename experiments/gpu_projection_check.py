"""The z-buffered projection's crack fill on the default device against the CPU.

Usage::

    python experiments/gpu_projection_check.py [--deterministic] [--size 32,96] [--grids 5,9]
        [--chain-map]

`forward_project_views` projects a smooth map with a near square (slanted surfaces, whose
rounding leaves 1-pixel cracks, and occluding edges) into the cross-hair views of a 5×5 and
a 9×9 grid. Prints, per dtype (float32, float64), grid, map size and formulation of the
crack fill: the cracks it fills on the CPU, how many output elements of the compiled forward
program and of the compiled gradient program (its forward pass, ``aux``) differ from the
CPU's, and the largest difference of the gradient of a loss of the projection from the
CPU's gradient, relative to the largest gradient element.

Formulations: ``none`` (no crack fill; the control), ``library``
(`mvedge_jax.lightfield._warp._fill_cracks`), and the same values by other operations:
``roll`` (neighbours by `jnp.roll` and border masks instead of pad and slice), ``coords``
(the winners' source rows and columns gathered from coordinate grids instead of integer
division), ``no-inf`` (a validity mask instead of the −∞ sentinel), ``float`` (no padding of
bool or int arrays; with ``no-inf``) and ``all`` (every one of these changes). Each is
checked bit-identical to ``library`` on the CPU; the script exits with an error where one
is not.

On an NVIDIA H200 with JAX 0.11.2 (docs/RESULTS.md, "GPU"), the cross-hair projection of a
32×32 float64 map compiled alone gave wrong crack fills in the forward program and a wrong
gradient (largest difference 0.69) in the gradient program; in float32 the outputs were
right and the gradient was as wrong; without the crack fill, and with
``XLA_FLAGS=--xla_backend_optimization_level=0``, both matched the CPU. Run this on a GPU to
see which formulation compiles right there; on the CPU it only checks that they agree.
"""

from __future__ import annotations

import argparse
import sys


def _variants(jnp):
    """The crack-fill formulations: name -> fill(vals, valid, src, dr, dc, crack_parallax);
    ``none`` (no crack fill) first, as the control."""
    from mvedge_jax.lightfield import _warp

    pairs = ((0, 1), (1, 0), (1, 1), (1, -1))

    def generic(vals, valid, src, dr, dc, crack_parallax, *, shift, coords, sentinel):
        K, H, W = vals.shape
        dtype = vals.dtype
        dr = dr.astype(dtype)[:, None, None]
        dc = dc.astype(dtype)[:, None, None]
        sy, sx = coords(src, H, W)
        norm = jnp.sqrt(dr * dr + dc * dc)
        best = jnp.zeros((K, H, W), dtype)
        have = jnp.zeros((K, H, W), bool)
        if sentinel:
            best = jnp.full((K, H, W), -jnp.inf, dtype)
        for ey, ex in pairs:
            va, vb = shift(valid, -ey, -ex, False), shift(valid, ey, ex, False)
            da, db = shift(vals, -ey, -ex, 0.0), shift(vals, ey, ex, 0.0)
            ya, yb = shift(sy, -ey, -ex, -10), shift(sy, ey, ex, 10)
            xa, xb = shift(sx, -ey, -ex, -10), shift(sx, ey, ex, 10)
            cheb = jnp.maximum(jnp.abs(ya - yb), jnp.abs(xa - xb))
            diff = jnp.abs(da - db)
            lo = jnp.minimum(da, db)
            ok = va & vb & (cheb == 1) & (diff * norm <= crack_parallax)
            ok = ok & (~valid | (vals < lo - diff))
            cand = 0.5 * (da + db)
            if sentinel:
                best = jnp.maximum(best, jnp.where(ok, cand, -jnp.inf))
            else:
                take = ok & (~have | (cand > best))
                best = jnp.where(take, cand, best)
                have = have | ok
        fill = best > -jnp.inf if sentinel else have
        return jnp.where(fill, best, vals), valid | fill

    def pad_shift(a, oy, ox, fillv):
        H, W = a.shape[1:]
        p = jnp.pad(a, ((0, 0), (1, 1), (1, 1)), constant_values=fillv)
        return p[:, 1 + oy : 1 + oy + H, 1 + ox : 1 + ox + W]

    def roll_shift(a, oy, ox, fillv):
        H, W = a.shape[1:]
        y = jnp.arange(H)[:, None] + oy
        x = jnp.arange(W)[None, :] + ox
        inside = (y >= 0) & (y < H) & (x >= 0) & (x < W)
        return jnp.where(inside, jnp.roll(a, (-oy, -ox), axis=(1, 2)), fillv)

    def float_shift(a, oy, ox, fillv):
        if a.dtype != bool:
            return pad_shift(a, oy, ox, fillv)
        return pad_shift(a.astype(jnp.float32), oy, ox, float(fillv)) > 0.5

    def divide(src, H, W):
        return src // W, src % W

    def gather(src, H, W):
        safe = jnp.maximum(src, 0)
        gy = jnp.repeat(jnp.arange(H, dtype=jnp.int32), W)
        gx = jnp.tile(jnp.arange(W, dtype=jnp.int32), H)
        return jnp.where(src >= 0, gy[safe], -1), jnp.where(src >= 0, gx[safe], W - 1)

    def float_coords(src, H, W):
        sy, sx = divide(src, H, W)
        return sy.astype(jnp.float32), sx.astype(jnp.float32)

    def roll_float_shift(a, oy, ox, fillv):
        if a.dtype != bool:
            return roll_shift(a, oy, ox, fillv)
        return roll_shift(a.astype(jnp.float32), oy, ox, float(fillv)) > 0.5

    def gather_float(src, H, W):
        sy, sx = gather(src, H, W)
        return sy.astype(jnp.float32), sx.astype(jnp.float32)

    def make(**kw):
        return lambda *a: generic(*a, **kw)

    return {
        "none": lambda vals, valid, *_: (vals, valid),
        "library": _warp._fill_cracks,
        "roll": make(shift=roll_shift, coords=divide, sentinel=True),
        "coords": make(shift=pad_shift, coords=gather, sentinel=True),
        "no-inf": make(shift=pad_shift, coords=divide, sentinel=False),
        "float": make(shift=float_shift, coords=float_coords, sentinel=False),
        "all": make(shift=roll_float_shift, coords=gather_float, sentinel=False),
    }


def _test_map(np, size: int):
    """A smooth ``(size, size)`` map (−1.2 to 1.2 px) with a near square: slanted surfaces
    crack under projection, the square's edges occlude."""
    y, x = np.mgrid[0:size, 0:size] / size
    d = 0.8 * np.sin(6.0 * x + 1.0) * np.cos(4.0 * y) + 0.3 * x
    q = slice(size // 4, size // 2)
    d[q, q] = 1.2 - 0.2 * y[q, q]
    return d


def _chain_map(np):
    """The chain's centre-view disparity at `chain_gradients.gradient_test_point` (32×32,
    float64, on the default device)."""
    from pathlib import Path

    import jax

    from mvedge_jax.pipeline import estimate_disparity_arrays, replace_paths

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from chain_gradients import gradient_test_point

    views, _, config, d_max, values0, _ = gradient_test_point()
    config = replace_paths(config, values0)
    out = estimate_disparity_arrays(views, config, key=jax.random.key(0), d_max=d_max)
    U, V = views.shape[:2]
    return np.asarray(out.disparity[U // 2, V // 2], np.float64)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--deterministic",
        action="store_true",
        help="request XLA's deterministic GPU kernels (no effect on the CPU)",
    )
    parser.add_argument("--size", default="32,96", help="comma-separated map sizes, pixels")
    parser.add_argument(
        "--grids", default="5,9", help="comma-separated cross-hair sizes (odd numbers of views)"
    )
    parser.add_argument(
        "--chain-map",
        action="store_true",
        help="also the centre-view map of the chain at experiments/chain_gradients.py's test "
        "point (5×5 grid, float64; one more compilation of the chain)",
    )
    args = parser.parse_args(argv)
    if args.deterministic:
        from mvedge_jax import request_deterministic_gpu

        request_deterministic_gpu()
    import jax
    import jax.numpy as jnp
    import numpy as np

    jax.config.update("jax_enable_x64", True)
    from mvedge_jax.lightfield import _warp

    sizes = [int(s) for s in args.size.split(",") if s]
    if not sizes or min(sizes) < 8:
        parser.error(f"--size needs map sizes of at least 8 pixels, got {args.size!r}")
    grids = [int(s) for s in args.grids.split(",") if s]
    if not grids or any(g < 3 or g % 2 == 0 for g in grids):
        parser.error(f"--grids needs odd numbers of views of at least 3, got {args.grids!r}")
    cpu = jax.devices("cpu")[0]
    device = jax.devices()[0]
    print(f"device: {device} (JAX {jax.__version__})")
    variants = _variants(jnp)

    def program(fill, offsets):
        def project(d):
            dr = jnp.asarray(offsets[:, 0])
            dc = jnp.asarray(offsets[:, 1])
            k = jnp.broadcast_to(d, (len(offsets), *d.shape))
            vals, valid, src = _warp._zbuffer(k, None, dr, dc)
            return fill(vals, valid, src, dr, dc, 0.5)

        def loss(d):
            vals, valid = project(d)
            return jnp.sum(jnp.sin(3.0 * vals) * valid), (vals, valid)

        return jax.jit(project), jax.jit(jax.value_and_grad(loss, has_aux=True))

    print(
        "| dtype | views | size | crack fill | cracks filled (CPU) | forward program != CPU |"
        " gradient program != CPU | gradient vs CPU, largest relative difference |"
    )
    print("|---|---|---|---|---|---|---|---|")
    failures = 0
    cases = [
        (t, g, n, _test_map(np, n).astype(t))
        for t in (np.float32, np.float64)
        for g in grids
        for n in sizes
    ]
    if args.chain_map:
        cases.append((np.float64, 5, "chain", _chain_map(np)))
    for dtype, grid, size, d in cases:
        steps = np.arange(grid) - grid // 2
        zeros = np.zeros(grid)
        offsets = np.concatenate([np.stack([zeros, steps], 1), np.stack([steps, zeros], 1)])
        reference, holes = [], 0
        for name, fill in variants.items():
            project, grad = program(fill, offsets)
            with jax.default_device(cpu):
                ref = [np.asarray(a) for a in project(jnp.asarray(d))]
                (_, _), ref_grad = grad(jnp.asarray(d))
                ref_grad = np.asarray(ref_grad)
            if name == "library":
                reference = ref
            elif name != "none" and not all(
                np.array_equal(a, b) for a, b in zip(ref, reference, strict=True)
            ):
                print(f"{name}: not bit-identical to library on the CPU", file=sys.stderr)
                failures += 1
            if device.platform == "cpu":
                out, aux, g = ref, ref, ref_grad
            else:
                x = jax.device_put(d, device)
                out = [np.asarray(a) for a in project(x)]
                (_, aux), g = grad(x)
                aux, g = [np.asarray(a) for a in aux], np.asarray(g)
            if name == "none":
                holes = int(np.sum(~ref[1]))
            filled = holes - int(np.sum(~ref[1]))
            n_out = sum(int(np.sum(a != b)) for a, b in zip(out, ref, strict=True))
            n_aux = sum(int(np.sum(a != b)) for a, b in zip(aux, ref, strict=True))
            rel = float(np.max(np.abs(g - ref_grad)) / max(np.max(np.abs(ref_grad)), 1e-300))
            row = (np.dtype(dtype).name, f"{grid}×{grid}", size, name, filled, n_out, n_aux)
            print("| " + " | ".join(map(str, row)) + f" | {rel:.1e} |", flush=True)
    if failures:
        sys.exit(f"{failures} formulations differ from the library's on the CPU")


if __name__ == "__main__":
    main()
