"""mvedge_jax: multi-view edge depth for 4D light fields, in JAX.

The stable public names are re-exported here (loaded on first use, so that ``import
mvedge_jax`` neither imports the stages nor starts a JAX backend); the stage packages
(`mvedge_jax.edges`, `.surface`, `.reconstruct`, `.diff`, `.solve`, `.metrics`, `.io`,
`.lightfield`, `.synthetic`, `.superpixels`) hold the rest. Importing the package enables
JAX's persistent compilation cache (`enable_compilation_cache`; set
``MVEDGE_JAX_CACHE=off`` to opt out).

References:
    N. Khan, "Are Multi-view Edges Incomplete?", PhD thesis, Brown University, 2022.
"""

from importlib import import_module
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _version

from ._cache import enable_compilation_cache as enable_compilation_cache
from ._determinism import deterministic_gpu_requested as deterministic_gpu_requested
from ._determinism import request_deterministic_gpu as request_deterministic_gpu

enable_compilation_cache()

try:
    __version__ = _version("mvedge_jax")
except PackageNotFoundError:  # a source tree that was not installed
    __version__ = "0.0.0+unknown"

#: Public name -> the subpackage that defines it.
_EXPORTS = {
    "ModelConfig": "diff",
    "OptimizeConfig": "diff",
    "EdgeConfig": "edges",
    "EdgeRefineConfig": "edges",
    "FilterConfig": "edges",
    "LabelConfig": "edges",
    "OutlierConfig": "edges",
    "EdgeSet": "edges",
    "detect_edges": "edges",
    "load_light_field": "io",
    "LightField": "lightfield",
    "depth_metrics": "metrics",
    "view_consistency": "metrics",
    "ChainOutput": "pipeline",
    "PipelineConfig": "pipeline",
    "Result": "pipeline",
    "estimate_disparity": "pipeline",
    "estimate_disparity_arrays": "pipeline",
    "optimize_disparity": "pipeline",
    "smooth_config": "pipeline",
    "sweep": "pipeline",
    "tune": "pipeline",
    "CentreConfig": "reconstruct",
    "EpiConfig": "reconstruct",
    "FillConfig": "reconstruct",
    "ReconstructConfig": "reconstruct",
    "SelectConfig": "reconstruct",
    "SharpenConfig": "reconstruct",
    "SurfaceConfig": "surface",
    "surface_vectors": "surface",
}

__all__ = [
    "__version__",
    "deterministic_gpu_requested",
    "enable_compilation_cache",
    "request_deterministic_gpu",
    *sorted(_EXPORTS),
]


def __getattr__(name: str):
    if name in _EXPORTS:
        value = getattr(import_module(f".{_EXPORTS[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'mvedge_jax' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
