"""gonio: a measured-BRDF pipeline.

Acquire reflectance with a gonioreflectometer (or its simulator), store it as tabulated BRDFs,
fit analytic models with uncertainty, and render fitted-vs-measured comparisons.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("gonio")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
