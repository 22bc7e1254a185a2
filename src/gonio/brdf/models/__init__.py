"""Analytic BRDF models (JAX). Each model lives in its own module; this package re-exports them.

>>> from gonio.brdf import models
>>> m = models.Lambert(albedo=[0.5, 0.4, 0.3])
"""

from gonio.brdf.models._base import BRDFModel, BRDFSample, Node, Param, registry
from gonio.brdf.models._sum import Sum
from gonio.brdf.models.blinn_phong import BlinnPhong
from gonio.brdf.models.lambert import Lambert
from gonio.brdf.models.oren_nayar import OrenNayar
from gonio.brdf.models.phong import Phong

__all__ = [
    "BRDFModel",
    "BRDFSample",
    "BlinnPhong",
    "Lambert",
    "Node",
    "OrenNayar",
    "Param",
    "Phong",
    "Sum",
    "registry",
]
