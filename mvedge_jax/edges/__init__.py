"""Multi-view edge detection on EPIs (thesis Ch. 4.1)."""

from ._bank import bank_width as bank_width
from ._bank import blur_images as blur_images
from ._bank import filter_disparities as filter_disparities
from ._bank import prewitt_bank as prewitt_bank
from ._config import STRATEGIES as STRATEGIES
from ._config import EdgeConfig as EdgeConfig
from ._detect import detect_centre_row as detect_centre_row
from ._detect import soft_detect as soft_detect
from ._detect import soft_select as soft_select
from ._edgeset import HORIZONTAL as HORIZONTAL
from ._edgeset import VERTICAL as VERTICAL
from ._edgeset import EdgeSet as EdgeSet
from ._edgeset import concatenate as concatenate
from ._fit import fit_lines as fit_lines
from ._pipeline import check_cross_hair as check_cross_hair
from ._pipeline import detect_edges as detect_edges
from ._pipeline import detect_edges_arrays as detect_edges_arrays
from ._pipeline import resolve_d_max as resolve_d_max
from ._pipeline import soft_edge_maps as soft_edge_maps
from ._pipeline import soft_filter_responses as soft_filter_responses
from ._pipeline import soft_labels as soft_labels
from ._pipeline import warn_dropped as warn_dropped
from ._render import point_errors as point_errors
from ._render import render_overlay as render_overlay
from ._render import render_sparse_disparity as render_sparse_disparity
