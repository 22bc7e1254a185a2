"""Rendering: spheres of measured or fitted BRDFs under studio lighting, and comparisons.

>>> from gonio.brdf import models
>>> from gonio.render import render_sphere, Directional, Environment
>>> img = render_sphere(models.Lambert(0.5), lights=[Environment("studio")], resolution=64)

The scene is a unit sphere seen from +z (DESIGN.md). Being convex, the sphere never shadows or
lights itself: direct lighting is the full solution, and that is what the integrator computes.
"""

from gonio.render.integrator import RenderStats, render_sphere
from gonio.render.lights import (
    Directional,
    Environment,
    Light,
    PointLight,
    SphereLight,
    studio_environment,
)
from gonio.render.scene import Camera, SphereHits, intersect_sphere

__all__ = [
    "Camera",
    "Directional",
    "Environment",
    "Light",
    "PointLight",
    "RenderStats",
    "SphereHits",
    "SphereLight",
    "intersect_sphere",
    "render_sphere",
    "studio_environment",
]
