"""Depth accuracy, view-consistency and light-field superpixel metrics (SPEC §3, §7)."""

from ._consistency import view_consistency as view_consistency
from ._depth import BADPIX_THRESHOLDS as BADPIX_THRESHOLDS
from ._depth import HCI_BADPIX_THRESHOLD as HCI_BADPIX_THRESHOLD
from ._depth import HCI_BORDER as HCI_BORDER
from ._depth import PROTOCOLS as PROTOCOLS
from ._depth import REGION_MASKS as REGION_MASKS
from ._depth import badpix as badpix
from ._depth import benchmark_metrics as benchmark_metrics
from ._depth import border_mask as border_mask
from ._depth import bumpiness_x100 as bumpiness_x100
from ._depth import depth_metrics as depth_metrics
from ._depth import mse_x100 as mse_x100
from ._depth import q25_hci_x100 as q25_hci_x100
from ._depth import q25_x100 as q25_x100
from ._depth import read_region_masks as read_region_masks
from ._scalefit import scale_fit_metrics as scale_fit_metrics
from ._superpixel import achievable_segmentation_accuracy as achievable_segmentation_accuracy
from ._superpixel import boundary_mask as boundary_mask
from ._superpixel import boundary_recall as boundary_recall
from ._superpixel import centroid_deviation_from_sums as centroid_deviation_from_sums
from ._superpixel import compactness as compactness
from ._superpixel import labels_per_pixel as labels_per_pixel
from ._superpixel import self_similarity_error as self_similarity_error
from ._superpixel import superpixel_metrics as superpixel_metrics
from ._superpixel import undersegmentation_error as undersegmentation_error
