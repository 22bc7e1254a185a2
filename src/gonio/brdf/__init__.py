"""Shared BRDF vocabulary: frames, analytic models, tabulated BRDFs and sampling.

This subpackage imports nothing else of gonio (except :mod:`gonio.errors`) and does no I/O.

Importing it enables JAX's 64-bit mode: fits run in float64 (DESIGN.md). Model code keeps the dtype
of the directions it is given, so rendering in float32 stays float32.
"""

import jax

jax.config.update("jax_enable_x64", True)

from gonio.brdf import frames  # noqa: E402

__all__ = ["frames"]
