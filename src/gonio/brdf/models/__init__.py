"""Analytic BRDF models (JAX). Each model lives in its own module; this package re-exports them.

>>> from gonio.brdf import models
>>> m = models.Lambert(albedo=[0.5, 0.4, 0.3])
"""

from gonio.brdf.models._base import BRDFModel, BRDFSample, Node, Param, registry
from gonio.brdf.models._sum import Sum
from gonio.brdf.models.fresnel import Conductor, Dielectric, Fresnel, NoFresnel, Schlick
from gonio.brdf.models.lambert import Lambert
from gonio.brdf.models.specular import SpecularReflection, SpecularTransmission
from gonio.brdf.models.torrance_sparrow import TorranceSparrow

__all__ = [
    "BRDFModel",
    "BRDFSample",
    "Conductor",
    "Dielectric",
    "Fresnel",
    "Lambert",
    "NoFresnel",
    "Node",
    "Param",
    "Schlick",
    "SpecularReflection",
    "SpecularTransmission",
    "Sum",
    "TorranceSparrow",
    "registry",
]
