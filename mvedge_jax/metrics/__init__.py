"""Depth accuracy and view-consistency metrics (SPEC §7)."""

from ._consistency import view_consistency as view_consistency
from ._depth import BADPIX_THRESHOLDS as BADPIX_THRESHOLDS
from ._depth import badpix as badpix
from ._depth import depth_metrics as depth_metrics
from ._depth import mse_x100 as mse_x100
from ._depth import q25_x100 as q25_x100
from ._scalefit import scale_fit_metrics as scale_fit_metrics
