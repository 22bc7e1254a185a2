"""Analytic BRDF models (JAX). Each model lives in its own module; this package re-exports them.

>>> from gonio.brdf import models
>>> m = models.Lambert(albedo=[0.5, 0.4, 0.3])
"""

from gonio.brdf.models._base import BRDFModel, BRDFSample, Node, Param, registry
from gonio.brdf.models._sum import Sum
from gonio.brdf.models.ashikhmin_shirley import AshikhminShirley
from gonio.brdf.models.ashikhmin_shirley_lobe import AshikhminShirleyLobe
from gonio.brdf.models.bagher_sgd import BagherSGD
from gonio.brdf.models.blinn_phong import BlinnPhong
from gonio.brdf.models.cook_torrance import CookTorrance
from gonio.brdf.models.fresnel import Conductor, Dielectric, Fresnel, NoFresnel, Schlick
from gonio.brdf.models.gtr import GTR
from gonio.brdf.models.htsg import HTSG
from gonio.brdf.models.lafortune import Lafortune
from gonio.brdf.models.lambert import Lambert
from gonio.brdf.models.low_microfacet import LowMicrofacet
from gonio.brdf.models.low_smooth import LowSmooth
from gonio.brdf.models.ngan_blinn_phong import NganBlinnPhong
from gonio.brdf.models.oren_nayar import OrenNayar
from gonio.brdf.models.phong import Phong
from gonio.brdf.models.retro import Retroreflection
from gonio.brdf.models.scaled import Scaled
from gonio.brdf.models.specular import SpecularReflection, SpecularTransmission
from gonio.brdf.models.torrance_sparrow import TorranceSparrow
from gonio.brdf.models.ward import Ward

__all__ = [
    "GTR",
    "HTSG",
    "AshikhminShirley",
    "AshikhminShirleyLobe",
    "BRDFModel",
    "BRDFSample",
    "BagherSGD",
    "BlinnPhong",
    "Conductor",
    "CookTorrance",
    "Dielectric",
    "Fresnel",
    "Lafortune",
    "Lambert",
    "LowMicrofacet",
    "LowSmooth",
    "NganBlinnPhong",
    "NoFresnel",
    "Node",
    "OrenNayar",
    "Param",
    "Phong",
    "Retroreflection",
    "Scaled",
    "Schlick",
    "SpecularReflection",
    "SpecularTransmission",
    "Sum",
    "TorranceSparrow",
    "Ward",
    "registry",
]
