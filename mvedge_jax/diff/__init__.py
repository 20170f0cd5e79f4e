"""Differentiable multi-view edge model (thesis Ch. 7).

Pipeline: points (position, label Z, R) → `render` (Gaussian label splat σ_S = 1.3 on a 7×7
support, super-Gaussian weight p = 2, σ_λ = 0.71, w = exp(-R); radiative transmittance
compositing with σ_Z = 1 and 8 quadrature samples, nearer points occluding farther ones,
rendered in parallel 8×8 tiles) → `predict` (eq 7.2 diffusion with ϑ = exp(-Q) through the
differentiable `mvedge_jax.solve.solve_poisson`) → losses (`supervised_loss`, eq 7.16
`self_supervised_loss`) → `optimize` (block-coordinate Adam over Z, positions, R, Q).
Unstructured input (Sec. 7.2.2): `sparse_depth_points` from a COLMAP model, `warp_by_depth`,
`multiview_loss` (eq 7.16 between posed views) and `optimize_multiview`.

Choices where the thesis leaves room (see the docstrings for details):

* The label Gaussian is truncated continuously (it reaches 0 at the edge of the 7×7 support)
  so that the render is continuous in the position.
* ``RenderConfig.label_mix = "weight"`` (default) mixes the labels at a pixel with the same
  occlusion-attenuated weights as λ^Z, so each point's label is exact where only its weight
  is non-zero (the ideal stated in Sec. 7.1.5); ``"opacity"`` is the literal eq 7.13
  (normalised by α).
* ρ (``density``) is not given by the thesis; the default 2 makes a point hide a farther one
  within ~1 px. Occlusion also hides visible neighbours of a nearer point, so for encoding a
  depth map whose points are all visible a small ρ (0.1) is much better.
* The depth order is piecewise constant: gradients reach depth only through the label values.
"""

from ..lightfield import ssim_map  # re-exported: the SSIM term of the loss
from ._composite import RenderResult, render
from ._config import RenderConfig
from ._loss import (
    LossConfig,
    edge_aware_smoothness,
    occlusion_mask,
    photometric_terms,
    self_supervised_loss,
    supervised_loss,
)
from ._model import (
    DiffParams,
    ModelConfig,
    Prediction,
    image_gradient_magnitude,
    initial_params,
    initial_q,
    predict,
    sample_bilinear,
    smoothness_weights,
)
from ._multiview import (
    MultiViewCameras,
    SparseDepth,
    intrinsics,
    multiview_cameras,
    multiview_loss,
    multiview_occlusion_mask,
    multiview_photometric_terms,
    optimize_multiview,
    project_points,
    relative_pose,
    sparse_depth_points,
    warp_by_depth,
)
from ._optimize import BLOCKS, OptimizeConfig, objective, optimize, params_from_edges
from ._splat import SplatResult, label_kernel_1d, splat, weight_kernel

__all__ = [
    "BLOCKS",
    "DiffParams",
    "LossConfig",
    "ModelConfig",
    "OptimizeConfig",
    "Prediction",
    "RenderConfig",
    "RenderResult",
    "MultiViewCameras",
    "SparseDepth",
    "SplatResult",
    "edge_aware_smoothness",
    "image_gradient_magnitude",
    "initial_params",
    "initial_q",
    "intrinsics",
    "label_kernel_1d",
    "multiview_cameras",
    "multiview_loss",
    "multiview_occlusion_mask",
    "multiview_photometric_terms",
    "objective",
    "occlusion_mask",
    "optimize",
    "optimize_multiview",
    "params_from_edges",
    "photometric_terms",
    "predict",
    "project_points",
    "relative_pose",
    "render",
    "sample_bilinear",
    "self_supervised_loss",
    "smoothness_weights",
    "sparse_depth_points",
    "splat",
    "ssim_map",
    "supervised_loss",
    "warp_by_depth",
    "weight_kernel",
]
