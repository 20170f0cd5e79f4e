"""Light-field container, EPI slicing and colour conversion."""

from ._colour import rgb_to_lab as rgb_to_lab
from ._lightfield import (
    LightField as LightField,
    horizontal_epis as horizontal_epis,
    vertical_epis as vertical_epis,
    view_offsets as view_offsets,
)
