"""End-to-end: a reduced ``gonio demo`` on the simulated rig, checked against its ground truth.

One reduced run (plan ``demo-quick``, built-in analytic material, small renders; the ``demo``
fixture of ``conftest.py``) is shared by the tests of this folder; they run in one xdist worker
(``xdist_group``), which builds it once.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from urllib.parse import unquote, urlparse

import numpy as np
import pytest

from gonio.demo import builtin_material
from tests.view.browser import CHROMEDRIVER, CHROMIUM, start

pytestmark = pytest.mark.xdist_group("demo-e2e")


def test_true_model_recovers_ground_truth_within_intervals(demo):
    """Every true parameter lies within its fitted interval at a family-wise level of 1 %.

    Seven scalars are checked at once: at 95 % each, one would miss about every third run by
    chance alone. The intervals are the fit's own (its standard deviations from the JSON),
    widened to a Sidak-corrected two-sided 1 % for the family.
    """
    from scipy import stats

    out, material, _ = demo
    truth = material.truth_params["lambert+ts"]
    # read the written fit file, not the in-memory summary: the file is the product
    doc = json.loads((out / "fits" / "lambert-ts.json").read_text())
    free = {k: v for k, v in truth.items() if k not in doc["fixed"]}
    n = sum(np.size(v) for v in free.values())
    z_crit = stats.norm.ppf(1 - (1 - (1 - 0.01) ** (1 / n)) / 2)
    for key, value in free.items():
        fit = np.asarray(doc["params"][key], dtype=float)
        std = np.asarray(doc["std"][key], dtype=float)
        assert np.all(np.isfinite(std) & (std > 0)), key  # a real interval, not a point
        z = (fit - np.asarray(value, dtype=float)) / std
        assert np.all(np.abs(z) < z_crit), (key, value, fit, std, z_crit)
        # the published 95 % intervals are the same Gaussian ones (nothing sits on a bound)
        lo, hi = (np.asarray(x, dtype=float) for x in doc["intervals"][key])
        np.testing.assert_allclose(hi - lo, 2 * 1.959964 * std, rtol=0.02)
    for key in set(truth) - set(free):  # held fixed at the truth
        assert doc["params"][key] == truth[key]
    assert 0.5 < doc["reduced_chi2"] < 2.0  # the true model fits to the noise level


def test_true_model_is_preferred_and_renders_closest(demo):
    out, _, summary = demo
    by = {m.preset: m for m in summary.models}
    assert [m.preset for m in summary.models] == [
        "lambert",
        "oren-nayar",
        "lambert+ward",
        "lambert+ts",
    ]
    best_bic = min(summary.models, key=lambda m: m.bic)
    assert best_bic.preset == "lambert+ts"
    tc = by["lambert+ts"].truth_check
    fixed = json.loads((out / "fits" / "lambert-ts.json").read_text())["fixed"]
    truth = builtin_material().truth_params["lambert+ts"]
    assert set(tc.z) == set(truth) - set(fixed)  # every free parameter is compared
    assert tc.n_scalars == 7 and tc.z_crit == pytest.approx(3.19, abs=0.01)
    assert tc.consistent  # the same verdict as the independent check of the JSON above
    # the diffuse-only fits cannot show the coat's highlight
    assert by["lambert+ts"].rmse < by["lambert"].rmse / 5
    assert by["lambert+ts"].ssim > by["lambert"].ssim
    # the appearance score agrees, and the report shows it
    assert by["lambert+ts"].hdr_flip < by["lambert"].hdr_flip
    assert by["lambert+ts"].rel_l1 < by["lambert"].rel_l1
    html = (out / "index.html").read_text(encoding="utf-8")
    assert "HDR-FLIP" in html and f"{by['lambert+ts'].hdr_flip:.3g}" in html


def test_outputs_exist_and_are_readable(demo):
    from gonio import io
    from gonio.brdf.measured import MeasuredSamples
    from gonio.render.output import read_exr

    out, _, summary = demo
    samples = io.load(out / "run" / "table.brdf.h5")
    assert isinstance(samples, MeasuredSamples)
    assert len(samples.values) == summary.acquisition["measured"] > 40
    acq = summary.acquisition
    assert acq["planned"] == acq["measured"] + acq["rejected"]
    for stem in ("measured", "lambert", "oren-nayar", "lambert-ward", "lambert-ts"):
        img = read_exr(out / "renders" / f"{stem}.exr")
        assert img.shape == (64, 64, 3) and np.isfinite(img).all() and img.max() > 0
        assert (out / "renders" / f"{stem}.png").stat().st_size > 0
    assert (out / "compare.png").is_file() and (out / "camera-view.png").is_file()
    doc = json.loads((out / "demo-summary.json").read_text())
    assert doc["material"]["name"] == "builtin-orange-paint"
    assert set(doc["timings_s"]) >= {"acquire", "fit", "render", "total"}
    # pruning kept the first configurations' images only; the table holds every sample
    kept = {p.name.split("_")[0].split(".")[0] for p in (out / "run" / "raw").iterdir()}
    assert 1 <= len(kept) <= 3


def test_fit_files_validate_against_the_published_schema(demo):
    import jsonschema

    from gonio.io.fit_result import schema_text

    out, _, _ = demo
    schema = json.loads(schema_text())
    for path in sorted((out / "fits").glob("*.json")):
        jsonschema.validate(json.loads(path.read_text()), schema)


def _local_refs(index: Path) -> list[tuple[str, str]]:
    import html5lib

    doc = html5lib.parse(index.read_text(encoding="utf-8"), namespaceHTMLElements=False)
    refs = [("img", e.get("src")) for e in doc.iter("img")]
    refs += [("a", e.get("href")) for e in doc.iter("a")]
    return refs


def test_report_is_valid_html_and_every_image_and_link_resolves(demo):
    import html5lib

    out, _, summary = demo
    index = out / "index.html"
    # the strict parser raises on any parse error of the HTML standard
    html5lib.HTMLParser(strict=True).parse(index.read_text(encoding="utf-8"))
    refs = _local_refs(index)
    assert len([r for r in refs if r[0] == "img"]) >= 5 + 1 + 4 * 3  # spheres, compare, plots
    for kind, ref in refs:
        assert ref, f"{kind} without a target"
        url = urlparse(ref)
        assert not url.scheme and not url.netloc, f"{ref}: the report must be self-contained"
        target = (out / unquote(url.path)).resolve()
        assert target.is_relative_to(out.resolve()), ref
        assert target.is_file(), f"{kind} {ref} does not resolve"
    text = index.read_text(encoding="utf-8")
    for m in summary.models:  # the numbers are on the page
        assert f"{m.reduced_chi2:.4g}" in text


def test_report_links_the_runs_view_page(demo):
    """index.html links view.html: a self-contained gonio view page (its CSP blocks every
    request, nothing outside it is referenced) of the run and every fit."""
    import html5lib

    out, _, summary = demo
    assert ("a", "view.html") in _local_refs(out / "index.html")
    text = (out / "view.html").read_text(encoding="utf-8")
    doc = html5lib.parse(text, namespaceHTMLElements=False)
    csp = [e.get("content") for e in doc.iter("meta") if e.get("http-equiv")]
    assert csp and csp[0].startswith("default-src 'none'"), csp
    for e in doc.iter():
        for attr in ("src", "href"):
            assert not e.get(attr) or not urlparse(e.get(attr)).scheme, (e.tag, e.get(attr))
    data = json.loads(text.split('id="gonio-data">', 1)[1].split("</script>", 1)[0])
    labels = [s["label"] for s in data["spheres"]]
    assert labels == ["run"] + [Path(m.files["fit"]).stem for m in summary.models], labels
    assert "coverage-0" in data["figures"]  # the run's sampled pairs


def test_report_survives_a_move(demo, tmp_path):
    out, _, _ = demo
    moved = tmp_path / "copy"
    shutil.copytree(out, moved)
    for _, ref in _local_refs(moved / "index.html"):
        assert (moved / unquote(urlparse(ref).path)).is_file(), ref


@pytest.mark.skipif(
    not (CHROMIUM.exists() and CHROMEDRIVER.exists()),
    reason="Debian's chromium and chromium-driver are not installed (/usr/bin/chromium, "
    "/usr/bin/chromedriver)",
)
def test_report_opens_in_headless_chromium_without_console_errors(demo, tmp_path):
    pytest.importorskip("selenium.webdriver", reason="selenium is not installed")

    out, _, _ = demo
    driver = start(tmp_path / "profile", window=(4000, 3000))
    try:
        driver.get((out / "index.html").resolve().as_uri())
        assert driver.title.startswith("gonio demo")
        images = driver.execute_script(
            "return Array.from(document.images).map(i => [i.src, i.complete, i.naturalWidth]);"
        )
        assert images and all(done and width > 0 for _, done, width in images), images
        # Every image is shown at its native size (no CSS downscaling, which aliases the
        # spheres' pixels and shrinks the plots' text), in a window wide enough for all of them.
        sizes = driver.execute_script(
            "return Array.from(document.images).map(i => [i.src, i.width, i.naturalWidth,"
            " i.height, i.naturalHeight]);"
        )
        scaled = [s for s in sizes if (s[1], s[3]) != (s[2], s[4])]
        assert not scaled, scaled
        errors = [e for e in driver.get_log("browser") if e["level"] in ("SEVERE", "ERROR")]
        assert not errors, errors
    finally:
        driver.quit()


def test_demo_refuses_a_foreign_non_empty_folder(tmp_path, capsys, monkeypatch):
    import gonio.demo.materials
    from gonio.cli import main

    def no_material(spec):  # the folder is checked first: no material is loaded for a refusal
        raise AssertionError(f"material {spec!r} loaded before the output folder was checked")

    monkeypatch.setattr(gonio.demo.materials, "find_material", no_material)
    keep = tmp_path / "mine" / "notes.txt"
    keep.parent.mkdir()
    keep.write_text("precious")
    rc = main(["demo", "--out", str(keep.parent), "--force", "--no-progress"])
    err = capsys.readouterr().err
    assert rc != 0 and err.count("\n") == 1 and "refusing to delete" in err
    assert keep.read_text() == "precious"


def test_demo_rejects_a_missing_material_file(tmp_path, capsys):
    from gonio.cli import main

    rc = main(["demo", "--out", str(tmp_path / "d"), "--material", str(tmp_path / "no.bsdf")])
    err = capsys.readouterr().err
    assert rc != 0 and "no such file" in err and err.count("\n") == 1
    assert not (tmp_path / "d").exists()


def test_demo_rejects_scattered_samples_as_material(tmp_path, capsys):
    from gonio.cli import main
    from tests.conftest import shared_file

    path = shared_file("cornell", "acryl_blue.brdf")
    rc = main(["demo", "--out", str(tmp_path / "d"), "--material", str(path)])
    err = capsys.readouterr().err
    assert rc != 0 and "scattered samples" in err and err.count("\n") == 1
    assert not (tmp_path / "d").exists()


def test_auto_material_prefers_rgl_data_and_falls_back_to_builtin(tmp_path, monkeypatch):
    from gonio.demo import find_material, materials
    from tests.conftest import shared_file

    felt = shared_file("rgl", "acrylic_felt_green_rgb.bsdf")
    monkeypatch.setattr(materials, "data_folders", lambda: [tmp_path, felt.parents[1]])
    m = find_material("auto")
    assert m.is_measured and m.table_path == felt.resolve() and "felt" in m.description.lower()
    monkeypatch.setattr(materials, "data_folders", lambda: [tmp_path])
    assert find_material("auto").name == "builtin-orange-paint"


def test_report_exports_every_fit_to_every_renderer(demo):
    from gonio.export import TARGETS

    out, _, summary = demo
    text = (out / "index.html").read_text(encoding="utf-8")
    assert "<h2>Export</h2>" in text
    for m in summary.models:
        rows = m.files["exports"]
        assert [r["target"] for r in rows] == list(TARGETS)
        for r in rows:
            assert r["mapping"] in ("exact", "refit")
            assert (r["refit_loss"] is None) == (r["mapping"] == "exact")
            for f in r["files"]:
                assert (out / f).is_file() and f'href="{f}"' in text
