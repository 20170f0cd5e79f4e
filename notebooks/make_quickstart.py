"""Build notebooks/quickstart.ipynb from the cells below and execute it in place.

Usage: python notebooks/make_quickstart.py
(tests/test_notebook.py executes the committed notebook and writes its outputs back.)
"""

from pathlib import Path

import nbformat
from nbclient import NotebookClient

CELLS = [
    (
        "md",
        """# mvedge_jax quickstart

Multi-view edge depth on a real light field (HCI 4D *backgammon*, a 5×5 crop of the views at
a quarter of the resolution so that the notebook runs in a few minutes on a CPU): detect EPI
edges, compute surface vectors, reconstruct disparity for every view (thesis Ch. 4 and 6),
look at the error, then differentiate the whole chain with respect to a hyperparameter and
evaluate it for two values at once with `vmap`.

`MVEDGE_NOTEBOOK_SCALE` sets the spatial scale (default 0.25).""",
    ),
    (
        "code",
        """import os
from pathlib import Path

import jax
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Image

from mvedge_jax import viz
from mvedge_jax.edges import resolve_d_max
from mvedge_jax.io import load_light_field
from mvedge_jax.metrics import depth_metrics
from mvedge_jax.pipeline import (
    PipelineConfig,
    edge_epi_figure,
    estimate_disparity,
    estimate_disparity_arrays,
    replace_paths,
)

DATA = Path(os.environ.get("MVEDGE_DATA", Path.cwd().parent.parent / "shared" / "data"))
if not DATA.is_dir():
    DATA = Path.cwd().parent / "shared" / "data"
scale = float(os.environ.get("MVEDGE_NOTEBOOK_SCALE", "0.25"))
lf = load_light_field(DATA / "hci4d" / "stratified" / "backgammon", scale=scale, views=(5, 5))
print(lf.name, "grid", lf.grid, "size", lf.size, "disparity range", lf.disparity_range)
print("device:", jax.devices()[0].device_kind)""",
    ),
    (
        "md",
        """## The main job

`estimate_disparity` compiles and runs the three stages and returns the disparity of every
view. Disparity is in pixels per view step of the loaded (scaled) views.""",
    ),
    (
        "code",
        """result = estimate_disparity(lf)
print("edge points:", int(result.edges.valid.sum()))
print("disparity of every view:", result.disparity.shape)
rc, cc = lf.centre_index
d = np.asarray(result.disparity[rc, cc])
gt = np.asarray(lf.centre_gt)
print({k: round(v, 3) for k, v in depth_metrics(d, gt).items()})""",
    ),
    (
        "code",
        """# One colour map and range for disparity, the HCI toolkit's colours for the error.
lo, hi = viz.colour_range(gt)
fig, ax = plt.subplots(1, 4, figsize=(17, 3.6), layout="constrained")
ax[0].imshow(np.asarray(lf.centre_view))
ax[0].set_title("centre view")
for a, img, title in ((ax[1], d, "estimated disparity"), (ax[2], gt, "ground truth")):
    im = a.imshow(img, cmap=viz.DISPARITY_CMAP, vmin=lo, vmax=hi, interpolation="nearest")
    a.set_title(title)
    fig.colorbar(im, ax=a, label=viz.DISPARITY_LABEL)
im = ax[3].imshow(gt - d, cmap=viz.ERROR_CMAP, vmin=-viz.ERROR_LIMIT, vmax=viz.ERROR_LIMIT,
                  interpolation="nearest")
ax[3].set_title("error (red: too far, blue: too near)")
fig.colorbar(im, ax=ax[3], label=viz.ERROR_LABEL)
for a in ax:
    a.axis("off")""",
    ),
    (
        "code",
        """# The horizontal EPI through the middle pixel row of the centre row of views, with the
# detected multi-view edge lines (the same figure `mvedge depth` writes as epi_horizontal.png).
H, W = lf.size
fig_md = edge_epi_figure(lf.views, result.edges, "horizontal", H // 2, vmin=lo, vmax=hi)
Image(viz.png_bytes(*fig_md))""",
    ),
    (
        "md",
        """## Differentiating the chain

`estimate_disparity_arrays` is the whole chain (edges → surface vectors → reconstruction) as
one pure function of arrays. The hyperparameters are arrays inside the frozen config, so
`jax.grad` and `jax.vmap` see them as ordinary inputs (`replace_paths` sets them by dotted
path). Here: the centre-view MSE×100 as a function of ω, the weight of the edge data term of
the centre-view diffusion (thesis eq 6.3). The Poisson solves differentiate through a custom
VJP (one adjoint solve). `vmap` evaluates the value and the gradient for two values of ω in
one call, compiled once. `docs/GRADIENTS.md` lists the fields the chain is smooth in.""",
    ),
    (
        "code",
        """cfg = PipelineConfig()
key = jax.random.key(0)
d_max = resolve_d_max(cfg.edges, lf.disparity_range)


def centre_error(omega, views, gt):
    # the arrays are arguments, not closed-over constants (which XLA would constant-fold)
    c = replace_paths(cfg, {"reconstruct.centre.omega": omega})
    disp = estimate_disparity_arrays(views, c, key=key, d_max=d_max).disparity
    return 100.0 * jnp.mean((disp[rc, cc] - gt) ** 2)


data = (lf.views, lf.centre_gt)
# grad: d(MSE×100)/dω; vmap: both for two values of ω in one compiled call
value_and_grad = jax.value_and_grad(centre_error)
batched = jax.jit(jax.vmap(value_and_grad, in_axes=(0, None, None)))
omegas = jnp.array([50.0, float(cfg.reconstruct.centre.omega)])
values, grads = batched(omegas, *data)
for w, v, g in zip(omegas, values, grads, strict=True):
    print(f"vmap: ω = {float(w):g}: MSE×100 {float(v):.4f}, d(MSE×100)/dω = {float(g):.3e}")""",
    ),
]


def build() -> nbformat.NotebookNode:
    """The notebook of `CELLS`, unexecuted."""
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
    nb = build()
    client = NotebookClient(
        nb, timeout=1800, kernel_name="python3", resources={"metadata": {"path": str(here)}}
    )
    client.execute()
    nbformat.write(nb, here / "quickstart.ipynb")
    print("wrote", here / "quickstart.ipynb")
