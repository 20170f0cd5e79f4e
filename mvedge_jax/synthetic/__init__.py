"""Procedural light fields with exact ground-truth disparity for every view."""

from ._multiview import MultiViewScene as MultiViewScene
from ._multiview import make_multiview_scene as make_multiview_scene
from ._multiview import write_multiview_scene as write_multiview_scene
from ._scene import DISC as DISC
from ._scene import RECT as RECT
from ._scene import WHOLE as WHOLE
from ._scene import Surface as Surface
from ._scene import default_light_field as default_light_field
from ._scene import make_scene as make_scene
from ._scene import render_surfaces as render_surfaces
