"""``gonio prior build`` and ``gonio reconstruct`` through the console script, and what fit and
render do with a reconstruction."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gonio import io
from gonio.cli import main
from tests import console_script as cs


@pytest.fixture(scope="module")
def files(tmp_path_factory, tables):
    d = tmp_path_factory.mktemp("prior-cli")
    for i, t in enumerate(tables[:5]):
        io.save(t, d / f"m{i}.brdf.h5")
    rng = np.random.default_rng(0)
    t = tables[5]
    mask = np.zeros(t.mask.shape, bool)
    mask.reshape(-1)[rng.choice(mask.size, 60, replace=False)] = True
    io.save(t.replace(mask=mask & t.mask), d / "sparse.brdf.h5")
    return d


def test_build_reconstruct_fit_render(files, capsys):
    d = files
    prior = d / "lib.prior.h5"
    args = [
        "prior",
        "build",
        *(str(d / f"m{i}.brdf.h5") for i in range(5)),
        "--out",
        str(prior),
        "--max-rank",
        "3",
        "--json",
    ]
    assert main(args) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["materials"] == 5 and 1 <= summary["rank"] <= 3
    assert main(args) == 2  # PRIOR exists: refused without --force
    assert "exists" in capsys.readouterr().err
    rec = d / "rec.brdf.h5"
    p = cs.run("reconstruct", d / "sparse.brdf.h5", "--prior", prior, "--out", rec)
    cs.assert_clean(p)
    assert "correlated" in p.stderr
    t = io.load(rec)
    assert t.sigma is not None and t.meta["sigma_correlated"]
    p = cs.run(
        "fit", rec, "--model", "lambert", "--out", d / "fit", "--no-plots", "--uncertainty", "none"
    )
    cs.assert_clean(p)
    assert "its sigma is correlated across cells" in p.stderr
    fit = json.loads((d / "fit" / "lambert.json").read_text())
    assert fit["data"]["sigma_ignored"]
    p = cs.run(
        "render",
        "--measured",
        rec,
        "--light",
        "dir:30,0",
        "--resolution",
        "16",
        "--spp",
        "2",
        "--out",
        d / "r.png",
    )
    cs.assert_clean(p)
    assert (d / "r.png").is_file()


def test_bad_prior_is_one_line(files, tmp_path):
    bad = tmp_path / "bad.prior.h5"
    bad.write_bytes(b"\x89HDF\r\n\x1a\n" + b"\0" * 100)
    out = tmp_path / "x.brdf.h5"
    p = cs.run("reconstruct", files / "sparse.brdf.h5", "--prior", bad, "--out", out)
    assert p.returncode != 0 and "Traceback" not in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1 and str(bad) in p.stderr
    assert not out.exists()
