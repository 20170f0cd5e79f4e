"""Build notebooks/quickstart.ipynb from the cells below and execute it in place.

Usage: python notebooks/make_quickstart.py   (the test suite executes the notebook itself)
"""

from pathlib import Path

import nbformat
from nbclient import NotebookClient

CELLS = [
    (
        "md",
        """# mvedge_jax quickstart

Multi-view edge depth on a real light field (HCI 4D *backgammon*): detect EPI edges, compute
surface vectors, reconstruct disparity for every view (thesis Ch. 4 and 6), look at the error,
and take a gradient of the error with respect to a hyperparameter.

`MVEDGE_NOTEBOOK_SCALE` sets the spatial scale (the test suite runs it at 0.25).""",
    ),
    (
        "code",
        """import os
from pathlib import Path

import jax
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np

from mvedge_jax import viz
from mvedge_jax.io import load_light_field
from mvedge_jax.metrics import depth_metrics
from mvedge_jax.pipeline import epi_overlay, estimate_disparity
from mvedge_jax.reconstruct import centre_disparity

DATA = Path(os.environ.get("MVEDGE_DATA", Path.cwd().parent.parent / "shared" / "data"))
if not DATA.is_dir():
    DATA = Path.cwd().parent / "shared" / "data"
scale = float(os.environ.get("MVEDGE_NOTEBOOK_SCALE", "0.5"))
lf = load_light_field(DATA / "hci4d" / "stratified" / "backgammon", scale=scale)
print(lf.name, lf.grid, lf.size, "disparity range", lf.disparity_range)""",
    ),
    (
        "code",
        """result = estimate_disparity(lf)
print("edge points:", int(result.edges.valid.sum()))
print("seconds per stage:", {k: round(v, 2) for k, v in result.seconds_per_stage.items()},
      "compile:", round(result.compile_seconds, 1))
rc, cc = lf.centre_index
d = np.asarray(result.disparity[rc, cc])
gt = np.asarray(lf.centre_gt)
print({k: round(v, 3) for k, v in depth_metrics(d, gt).items()})""",
    ),
    (
        "code",
        """fig, ax = plt.subplots(1, 4, figsize=(16, 4))
ax[0].imshow(np.asarray(lf.centre_view)); ax[0].set_title("centre view")
lo, hi = np.percentile(gt, [1, 99])
ax[1].imshow(viz.colorize_disparity(d, vmin=lo, vmax=hi)); ax[1].set_title("disparity")
ax[2].imshow(viz.colorize_disparity(gt, vmin=lo, vmax=hi)); ax[2].set_title("ground truth")
ax[3].imshow(viz.error_map(d, gt, limit=0.2)); ax[3].set_title("error (±0.2 px)")
for a in ax: a.axis("off")""",
    ),
    (
        "code",
        """# A horizontal EPI (centre row of views, pixel row H/2) with the detected lines.
H, W = lf.size
plt.figure(figsize=(14, 3))
plt.imshow(epi_overlay(np.asarray(lf.views), result.edges, "horizontal", H // 2))
plt.title("EPI with multi-view edge lines"); plt.axis("off");""",
    ),
    (
        "code",
        """# Gradient of the centre-view error w.r.t. two hyperparameters of eqs 6.1-6.3, through
# the differentiable Poisson solve (custom VJP: one adjoint solve, no unrolled iterations).
import equinox as eqx

from mvedge_jax.reconstruct import ReconstructConfig

cfg = ReconstructConfig()


def centre_mse(omega, centre_c, edges, surface, view, gt):
    c = eqx.tree_at(lambda k: (k.omega, k.centre_c), cfg, (omega, centre_c))
    dd = centre_disparity(edges, surface, view, c)
    return 100.0 * jnp.mean((dd - gt) ** 2)


grad_fn = jax.jit(jax.value_and_grad(centre_mse, argnums=(0, 1)))
val, grads = grad_fn(cfg.omega, cfg.centre_c, result.edges, result.surface, lf.centre_view,
                     lf.centre_gt)
print(f"MSE×100 of the diffused centre view (before sharpening) {float(val):.3f}")
print(f"d/dω = {float(grads[0]):.3e}, d/dc = {float(grads[1]):.3e}")""",
    ),
]


def build(path: Path) -> nbformat.NotebookNode:
    nb = nbformat.v4.new_notebook()
    nb.cells = [
        nbformat.v4.new_markdown_cell(src) if kind == "md" else nbformat.v4.new_code_cell(src)
        for kind, src in CELLS
    ]
    nb.metadata["kernelspec"] = {
        "name": "python3",
        "display_name": "Python 3",
        "language": "python",
    }
    return nb


if __name__ == "__main__":
    here = Path(__file__).resolve().parent
    nb = build(here / "quickstart.ipynb")
    client = NotebookClient(
        nb, timeout=1800, kernel_name="python3", resources={"metadata": {"path": str(here)}}
    )
    client.execute()
    nbformat.write(nb, here / "quickstart.ipynb")
    print("wrote", here / "quickstart.ipynb")
