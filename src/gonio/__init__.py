"""gonio: a measured-BRDF pipeline.

Acquire reflectance with a gonioreflectometer (or its simulator), store it as tabulated BRDFs,
fit analytic models with uncertainty, and render fitted-vs-measured comparisons.
"""

__all__ = ["__version__"]


def __getattr__(name: str):
    # looked up on first use: importing importlib.metadata is a noticeable part of a light
    # command's start (benchmarks/bench_startup.py), and `python -m gonio` installs
    # its signal handlers only after this package is imported (see gonio/__main__.py)
    if name == "__version__":
        from importlib.metadata import PackageNotFoundError, version

        try:
            v = version("gonio")
        except PackageNotFoundError:  # running from a source tree that was never installed
            v = "0.0.0+unknown"
        globals()["__version__"] = v
        return v
    raise AttributeError(f"module 'gonio' has no attribute {name!r}")
