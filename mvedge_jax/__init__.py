"""mvedge_jax: multi-view edge depth for 4D light fields in JAX."""

from importlib.metadata import version as _version

__version__ = _version("mvedge_jax")
