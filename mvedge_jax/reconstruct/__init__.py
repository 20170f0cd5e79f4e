"""Smooth 4D reconstruction from the multi-view edge model (thesis Ch. 6)."""

from ._centre import centre_disparity as centre_disparity
from ._config import CentreConfig as CentreConfig
from ._config import EpiConfig as EpiConfig
from ._config import FillConfig as FillConfig
from ._config import ReconstructConfig as ReconstructConfig
from ._config import SelectConfig as SelectConfig
from ._config import SharpenConfig as SharpenConfig
from ._crosshair import inpaint_epis as inpaint_epis
from ._crosshair import photometric_confidence as photometric_confidence
from ._crosshair import project_cross_hair as project_cross_hair
from ._crosshair import rasterise_lines as rasterise_lines
from ._matte import boundary_matte as boundary_matte
from ._oracle import OracleSurface as OracleSurface
from ._oracle import oracle_edges as oracle_edges
from ._photo import photo_cost as photo_cost
from ._photo import photo_refine as photo_refine
from ._photo import photo_select as photo_select
from ._reconstruct import Reconstruction as Reconstruction
from ._reconstruct import background_fill as background_fill
from ._reconstruct import propagate as propagate
from ._reconstruct import reconstruct as reconstruct
from ._reconstruct import select_centre as select_centre
from ._reconstruct import sharpen as sharpen
from ._wmf import weighted_mean_filter as weighted_mean_filter
from ._wmf import weighted_median_filter as weighted_median_filter
