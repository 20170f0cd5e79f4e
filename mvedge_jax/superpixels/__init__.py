"""View-consistent 4D light-field superpixels (thesis Ch. 5, Sec. 4.2.1).

Occlusion-aware EPI segmentation (`segment_epis`, `render_segments`), spatio-angular
clustering and label propagation (`superpixels`), and the k-means baseline
(`kmeans_superpixels`).
"""

from ._config import SuperpixelConfig as SuperpixelConfig
from ._label import forward_labels as forward_labels
from ._label import nearest_fill as nearest_fill
from ._label import propagate_labels as propagate_labels
from ._render import draw_boundaries as draw_boundaries
from ._render import label_colours as label_colours
from ._render import view_sweep as view_sweep
from ._segment import EPISegments as EPISegments
from ._segment import match_lines as match_lines
from ._segment import render_segments as render_segments
from ._segment import resolve_unknown as resolve_unknown
from ._segment import segment_epis as segment_epis
from ._superpixels import SuperpixelResult as SuperpixelResult
from ._superpixels import kmeans_superpixels as kmeans_superpixels
from ._superpixels import superpixels as superpixels
