"""File formats: HCI 4D, old HCI, view grids, PFM, PNG. The only package that touches files."""

from ._grid import read_view_grid as read_view_grid
from ._hci import read_hci4d as read_hci4d
from ._hci_old import depth_to_disparity as depth_to_disparity
from ._hci_old import read_hci_old as read_hci_old
from ._hci_old import read_hci_old_depth as read_hci_old_depth
from ._images import read_rgb as read_rgb
from ._images import read_views as read_views
from ._images import write_png as write_png
from ._layout import LayoutInfo as LayoutInfo
from ._layout import detect_layout as detect_layout
from ._layout import read_hci_old_attributes as read_hci_old_attributes
from ._layout import read_hci_parameters as read_hci_parameters
from ._load import crop_window as crop_window
from ._load import load_light_field as load_light_field
from ._load import load_light_field_with_info as load_light_field_with_info
from ._load import orient as orient
from ._orient import ParallaxCheck as ParallaxCheck
from ._orient import check_parallax_axes as check_parallax_axes
from ._pfm import read_pfm as read_pfm
from ._pfm import write_pfm as write_pfm
from ._results import OutputWriter as OutputWriter
from ._results import check_output_dir as check_output_dir
