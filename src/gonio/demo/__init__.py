"""``gonio demo``: the whole pipeline on the simulated rig (acquire, fit, render, report).

>>> from gonio.demo import find_material, run_demo, DemoSettings
>>> material = find_material("builtin")  # or "auto", or a table file
>>> summary = run_demo("gonio-demo", material, DemoSettings.quick())  # doctest: +SKIP
"""

from gonio.demo.materials import DemoMaterial, builtin_material, find_material
from gonio.demo.pipeline import MODELS, DemoSettings, DemoSummary, run_demo

__all__ = [
    "MODELS",
    "DemoMaterial",
    "DemoSettings",
    "DemoSummary",
    "builtin_material",
    "find_material",
    "run_demo",
]
