"""Procedural light fields with exact ground-truth disparity for every view."""

from ._scene import DISC as DISC
from ._scene import RECT as RECT
from ._scene import WHOLE as WHOLE
from ._scene import Surface as Surface
from ._scene import default_light_field as default_light_field
from ._scene import make_scene as make_scene
from ._scene import render_surfaces as render_surfaces
from ._variants import VARIANTS, variant_scene, variant_scenes  # noqa: F401
