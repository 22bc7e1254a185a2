"""MaterialX validates the OpenPBR document; usd-core opens the layer and every value reads back."""

from __future__ import annotations

import numpy as np
import pytest

from gonio.brdf import models
from gonio.export import to_openpbr, to_usd
from tests.export.conftest import fit_record

SCHLICK = models.Schlick([0.04, 0.05, 0.06])


def _ggx(alpha=0.2, fresnel=SCHLICK):
    return models.TorranceSparrow(
        alpha=alpha, distribution="ggx", shadowing="smith", fresnel=fresnel
    )


OPENPBR_CASES = {
    "diffuse": models.Lambert(albedo=[0.5, 0.4, 0.3]),
    "metal": _ggx(0.3, models.Schlick([0.9, 0.6, 0.3])),
    "mix": models.Scaled(models.Lambert(albedo=[0.5, 0.4, 0.3]), 0.5)
    + models.Scaled(_ggx(0.2), 0.5),
}


@pytest.fixture(scope="module")
def mx():
    mx = pytest.importorskip("MaterialX", reason="materialx not installed (.[interop])")
    return mx


@pytest.fixture(scope="module")
def stdlib(mx):
    lib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
    return lib


def _read(mx, stdlib, text):
    doc = mx.createDocument()
    mx.readFromXmlString(doc, text)
    doc.importLibrary(stdlib)
    return doc


@pytest.mark.parametrize("key", list(OPENPBR_CASES))
def test_mtlx_validates(mx, stdlib, key):
    e = to_openpbr(fit_record(OPENPBR_CASES[key]))
    assert e.mapping == "exact"
    doc = _read(mx, stdlib, e.text)
    ok, message = doc.validate()
    assert ok, message
    shaders = [n for n in doc.getNodes() if n.getCategory() == "open_pbr_surface"]
    assert len(shaders) == (2 if key == "mix" else 1)
    for node in shaders:
        nd = node.getNodeDef()
        assert nd is not None and nd.getName() == "ND_open_pbr_surface_surfaceshader"
        for inp in node.getInputs():
            decl = nd.getActiveInput(inp.getName())
            assert decl is not None and decl.getType() == inp.getType(), inp.getName()
        written = e.params[node.getName()]
        for name, value in written.items():
            got = node.getInputValue(name)
            got = list(got.asTuple()) if hasattr(got, "asTuple") else got
            assert np.allclose(got, value, rtol=1e-6), name  # MaterialX holds float32
    (material,) = [n for n in doc.getNodes() if n.getCategory() == "surfacematerial"]
    assert material.getName() == e.name


def test_mtlx_mapping(mx, stdlib):
    e = to_openpbr(fit_record(OPENPBR_CASES["metal"]))
    p = e.params[f"{e.name}_metal"]
    assert p["specular_roughness"] == pytest.approx(np.sqrt(0.3))
    assert p["base_color"] == pytest.approx([0.9, 0.6, 0.3])
    assert p["base_metalness"] == 1.0 and p["specular_color"] == [1.0, 1.0, 1.0]


def test_broken_mtlx_fails_validation(mx, stdlib):
    """The validation used above does catch a wrong type."""
    e = to_openpbr(fit_record(OPENPBR_CASES["mix"]))
    bad = e.text.replace('name="mix" type="float"', 'name="mix" type="color3"')
    assert not _read(mx, stdlib, bad).validate()[0]


def test_usda_reads_back(tmp_path):
    pytest.importorskip("pxr", reason="usd-core not installed (.[interop])")
    from pxr import Sdf, Usd, UsdShade

    model = models.Lambert(albedo=[0.5, 0.4, 0.3]) + _ggx(0.2)
    e = to_usd(fit_record(model))
    assert e.mapping == "exact"
    (path,) = e.write(tmp_path / "m.usda")
    stage = Usd.Stage.Open(str(path))
    assert stage is not None
    assert stage.GetDefaultPrim().GetName() == e.name
    mat = UsdShade.Material(stage.GetPrimAtPath(f"/{e.name}"))
    shader = mat.ComputeSurfaceSource()[0]
    assert shader.GetIdAttr().Get() == "UsdPreviewSurface"
    inputs = {i.GetBaseName(): i.Get() for i in shader.GetInputs()}
    assert set(inputs) == set(e.params)
    for name, value in e.params.items():
        assert np.allclose(np.asarray(inputs[name], dtype=np.float64), value, rtol=1e-7), name
    assert inputs["roughness"] == pytest.approx(np.sqrt(0.2), rel=1e-7)
    assert list(inputs["diffuseColor"]) == pytest.approx([0.5, 0.4, 0.3])
    assert list(inputs["specularColor"]) == pytest.approx([0.04, 0.05, 0.06])
    assert shader.GetInput("diffuseColor").GetTypeName() == Sdf.ValueTypeNames.Color3f
