"""mvedge_jax: multi-view edge depth for 4D light fields, in JAX.

The stable public names are re-exported here; the stage packages (`mvedge_jax.edges`,
`.surface`, `.reconstruct`, `.diff`, `.solve`, `.metrics`, `.io`, `.lightfield`,
`.synthetic`) hold the rest. Importing the package enables JAX's persistent compilation
cache (`enable_compilation_cache`; set ``MVEDGE_JAX_CACHE=off`` to opt out).

References:
    N. Khan, "Are Multi-view Edges Incomplete?", PhD thesis, Brown University, 2022.
"""

from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _version

from ._cache import enable_compilation_cache as enable_compilation_cache

enable_compilation_cache()

from .diff import ModelConfig as ModelConfig  # noqa: E402
from .diff import OptimizeConfig as OptimizeConfig  # noqa: E402
from .edges import EdgeConfig as EdgeConfig  # noqa: E402
from .edges import EdgeSet as EdgeSet  # noqa: E402
from .edges import detect_edges as detect_edges  # noqa: E402
from .io import load_light_field as load_light_field  # noqa: E402
from .lightfield import LightField as LightField  # noqa: E402
from .metrics import depth_metrics as depth_metrics  # noqa: E402
from .metrics import view_consistency as view_consistency  # noqa: E402
from .pipeline import ChainOutput as ChainOutput  # noqa: E402
from .pipeline import PipelineConfig as PipelineConfig  # noqa: E402
from .pipeline import Result as Result  # noqa: E402
from .pipeline import estimate_disparity as estimate_disparity  # noqa: E402
from .pipeline import estimate_disparity_arrays as estimate_disparity_arrays  # noqa: E402
from .pipeline import optimize_disparity as optimize_disparity  # noqa: E402
from .pipeline import smooth_config as smooth_config  # noqa: E402
from .reconstruct import ReconstructConfig as ReconstructConfig  # noqa: E402
from .reconstruct import reconstruct as reconstruct  # noqa: E402
from .surface import SurfaceConfig as SurfaceConfig  # noqa: E402
from .surface import surface_vectors as surface_vectors  # noqa: E402

try:
    __version__ = _version("mvedge_jax")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0.0.0+unknown"
