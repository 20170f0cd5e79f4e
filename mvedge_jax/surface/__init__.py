"""Surface vectors by bidirectional diffusion, depth-edge confidence (thesis Ch. 4.2–4.3)."""

from ._surface import (
    SurfaceConfig as SurfaceConfig,
)
from ._surface import (
    SurfaceResult as SurfaceResult,
)
from ._surface import (
    gradient_directions as gradient_directions,
)
from ._surface import (
    side_score as side_score,
)
from ._surface import (
    splat_labels as splat_labels,
)
from ._surface import (
    step_responses as step_responses,
)
from ._surface import (
    surface_vectors as surface_vectors,
)
