"""Procedural light fields with exact ground-truth disparity and object IDs for every view."""

from ._multiview import MultiViewScene as MultiViewScene
from ._multiview import make_multiview_scene as make_multiview_scene
from ._multiview import write_multiview_scene as write_multiview_scene
from ._scene import DISC as DISC
from ._scene import N_SHADE as N_SHADE
from ._scene import RECT as RECT
from ._scene import WHOLE as WHOLE
from ._scene import Surface as Surface
from ._scene import default_light_field as default_light_field
from ._scene import default_surfaces as default_surfaces
from ._scene import make_scene as make_scene
from ._scene import make_scene_with_objects as make_scene_with_objects
from ._scene import render_coverage as render_coverage
from ._scene import render_object_ids as render_object_ids
from ._scene import render_surfaces as render_surfaces
from ._scene import scene_surfaces as scene_surfaces
from ._variants import GLOSS_AMPLITUDE as GLOSS_AMPLITUDE
from ._variants import GLOSS_NOISE as GLOSS_NOISE
from ._variants import GLOSS_WAVELENGTH as GLOSS_WAVELENGTH
from ._variants import VARIANTS, variant_scene, variant_scenes, variant_surfaces  # noqa: F401
