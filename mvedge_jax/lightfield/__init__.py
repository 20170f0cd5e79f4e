"""Light-field container, EPI slicing, colour conversion and view warping."""

from ._colour import linear_to_srgb as linear_to_srgb
from ._colour import rgb_to_lab as rgb_to_lab
from ._colour import srgb_to_linear as srgb_to_linear
from ._lightfield import LightField as LightField
from ._lightfield import horizontal_epis as horizontal_epis
from ._lightfield import vertical_epis as vertical_epis
from ._lightfield import view_offsets as view_offsets
from ._ssim import ssim_dissimilarity as ssim_dissimilarity
from ._ssim import ssim_map as ssim_map
from ._warp import GpuCompileWarning as GpuCompileWarning
from ._warp import backward_warp as backward_warp
from ._warp import backward_warp_planar as backward_warp_planar
from ._warp import forward_project as forward_project
from ._warp import forward_project_views as forward_project_views
