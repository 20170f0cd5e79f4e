"""Surface vectors by bidirectional diffusion, depth-edge confidence (thesis Ch. 4.2–4.3)."""

from ._surface import (
    SurfaceConfig as SurfaceConfig,
    SurfaceResult as SurfaceResult,
    gradient_directions as gradient_directions,
    splat_labels as splat_labels,
    step_responses as step_responses,
    surface_vectors as surface_vectors,
)
