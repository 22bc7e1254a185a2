"""The family x target table: generated from the targets' checks, equal to what the fitter
builds, shown in ``gonio export --help`` and in docs/guide/export.md, and true for Mitsuba's
exact cells by Mitsuba's own ``BSDF.eval``."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from gonio.export import export, registry, table
from gonio.export._lobes import NotRepresentable, split
from gonio.fit import presets
from tests.export.conftest import fit_record

GUIDE = Path(__file__).resolve().parents[2] / "docs" / "guide" / "export.md"


def test_the_table_lists_every_family_the_fitter_offers():
    assert list(table.FAMILIES) == presets.available()


@pytest.mark.parametrize("family", table.FAMILIES)
def test_the_table_sees_each_family_as_the_exporter_does(family):
    described = table.family_lobes(family)
    try:
        lobes = split(presets.build(family)[0])
    except NotRepresentable as exc:
        assert isinstance(described, str)
        assert str(exc).removeprefix("a ").split(" ")[0] in described
        return
    assert not isinstance(described, str)
    assert (lobes.diffuse is None) == (described.diffuse is None)
    assert (lobes.specular is None) == (described.specular is None)
    if lobes.specular is not None:
        a, b = lobes.specular, described.specular
        assert (a.distribution, a.shadowing, a.fresnel) == (b.distribution, b.shadowing, b.fresnel)


def test_every_cell_is_exact_plugin_or_a_refit_with_its_reason():
    cells = table.cells()
    assert set(cells) == set(table.FAMILIES)
    for row in cells.values():
        assert list(row) == registry.names()
        for c in row.values():
            assert c.kind in ("exact", "plugin", "refit")
            assert (c.reason is not None) == (c.kind != "exact")
    assert cells["lambert+ts-ggx-smith"]["blender"].kind == "exact"
    assert cells["ts-ggx-smith"]["mitsuba"].kind == "exact"  # principled, metallic 1


def test_plugin_cells_are_what_the_plugin_supports():
    """Every ``plugin`` cell's family is one the plugin's own ``supports`` accepts (RGB)."""
    from gonio.export import mitsuba_plugin

    for family, row in table.cells().items():
        if row["mitsuba"].kind == "plugin":
            assert mitsuba_plugin.supports(presets.build(family)[0]), family
    assert table.cells()["lambert+gtr"]["mitsuba"].kind == "plugin"


def test_the_guide_shows_the_generated_table():
    text = GUIDE.read_text(encoding="utf-8")
    m = re.search(r"<!-- export:families -->\n(.*?)\n<!-- /export:families -->", text, re.S)
    assert m, f"{GUIDE} has no <!-- export:families --> section"
    assert m.group(1) == table.markdown(), (
        "docs/guide/export.md's family table differs from gonio.export.table: paste"
        " `python -c 'from gonio.export.table import markdown; print(markdown())'`"
    )


def test_help_shows_the_table():
    from gonio.export.cli import epilog

    assert table.text() in epilog(registry.targets())


MITSUBA_EXACT = [f for f, row in table.cells().items() if row["mitsuba"].kind == "exact"]


def exact_cell_model(family: str):
    """``family``'s model with the values the exact-cell checks use."""
    model = presets.build(family)[0]
    values = {"albedo": [0.6, 0.45, 0.3], "alpha": 0.3, "f0": [0.9, 0.6, 0.3]}
    return model.replace(
        **{k: values[k.rsplit(".", 1)[-1]] for k in model.param_specs() if
           k.rsplit(".", 1)[-1] in values}
    )  # fmt: skip


@pytest.mark.parametrize("family", MITSUBA_EXACT)
def test_mitsuba_exact_cells_by_bsdf_eval(family):
    """Every exact Mitsuba cell: ``BSDF.eval`` of the export within 2 % relative RMSE of gonio's
    f cos over the sphere's pixels under lights at 0, 30 and 60 degrees."""
    pytest.importorskip("mitsuba")
    from tests.export.mitsuba_eval import directions, gonio_values, mitsuba_values, rel_rmse

    model = exact_cell_model(family)
    e = export(fit_record(model), "mitsuba")
    assert e.mapping == "exact"
    wi, wo = directions()
    err = rel_rmse(mitsuba_values(e.data, wi, wo), gonio_values(model, wi, wo))
    assert err <= 0.02, err


@pytest.mark.parametrize("family", MITSUBA_EXACT)
def test_mitsuba_exact_cells_under_the_studio(family):
    """Every exact Mitsuba cell under gonio's studio environment: the sphere image as the fixed
    sum over the appearance studio's directions (24 px, 70 per pixel) of radiance x ``f cos``,
    Mitsuba's ``BSDF.eval`` of the export against gonio's f, within 2 % relative RMSE."""
    pytest.importorskip("mitsuba")
    from tests.export.mitsuba_eval import (
        gonio_values,
        mitsuba_values,
        rel_rmse,
        studio_image,
        studio_pairs,
    )

    model = exact_cell_model(family)
    e = export(fit_record(model), "mitsuba")
    assert e.mapping == "exact"
    wi, wo, weight, pixel = studio_pairs(24, 70)
    got = studio_image(mitsuba_values(e.data, wi, wo), weight, pixel)
    err = rel_rmse(got, studio_image(gonio_values(model, wi, wo), weight, pixel))
    assert err <= 0.02, err


@pytest.mark.parametrize(("alpha", "exact"), [(0.45, True), (0.5, False)])
def test_mitsuba_ggx_is_exact_only_where_its_smith_term_agrees(alpha, exact):
    """Mitsuba's separable Smith term: GGX up to alpha 0.45 within 2 %, refused above."""
    pytest.importorskip("mitsuba")
    from gonio.brdf import models
    from gonio.export import mitsuba
    from gonio.export._lobes import split as lobes_of
    from tests.export.mitsuba_eval import directions, gonio_values, mitsuba_values, rel_rmse

    model = models.TorranceSparrow(
        alpha=alpha, distribution="ggx", shadowing="smith", fresnel=models.Schlick([0.9, 0.6, 0.3])
    )
    lobes = lobes_of(model)
    assert (mitsuba.check(lobes) is None) == exact
    wi, wo = directions()
    bsdf, _ = mitsuba.bsdf_dict(lobes)
    err = rel_rmse(mitsuba_values(bsdf, wi, wo), gonio_values(model, wi, wo))
    assert (err <= 0.02) == exact, err


@pytest.mark.parametrize(("alpha", "family"), [(0.3, "ggx"), (0.52, "beckmann")])
def test_mitsuba_refits_a_rough_ggx_result_as_beckmann(alpha, family):
    """A GGX refit that ends above GGX_ALPHA_MAX (a felt's default fit did, at 0.52) is refitted
    from the template Mitsuba names for that result: Beckmann, which it can hold exactly."""
    from gonio.brdf import models
    from gonio.export import mitsuba

    rough = models.Lambert(0.3) + models.TorranceSparrow(
        alpha=alpha, distribution="ggx", shadowing="smith", fresnel=models.Conductor(1.5, 0.0)
    )
    tmpl, _, name = mitsuba.refit_template(rough, split(rough))
    assert f"TorranceSparrow({family}," in name
    assert family in repr(tmpl)
