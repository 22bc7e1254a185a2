"""Issue 40, item 4: the MCMC posterior's likelihood is the fitted loss, so the optimizer's
optimum lies inside its own intervals; the walkers start over the prior box. Fast: the ALTA
slice of pink felt through the console script (before: 4 of 7 estimates outside their
intervals). Slow (``-m slow``): every RGL, Cornell and ALTA file of the shared data and six NBRDF
materials (``benchmarks/bench_mcmc_agreement.py`` records the same with timings)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests import console_script as cs
from tests.conftest import SHARED_DATA, shared_file


def _inside(rec: dict) -> list[str]:
    """Flat names whose estimate lies outside its 95 % interval (unconstrained ones excluded)."""
    out = []
    for key, (lo, hi) in rec["intervals"].items():
        v = np.ravel(rec["params"][key])
        lo, hi = np.ravel(lo), np.ravel(hi)
        for i, x in enumerate(v):
            if lo[i] is None or hi[i] is None:
                continue
            if not lo[i] <= x <= hi[i]:
                out.append(f"{key}[{i}]")
    return out


@pytest.fixture(scope="module")
def felt(tmp_path_factory):
    path = shared_file("alta", "pink-felt-1d.alta")
    out = tmp_path_factory.mktemp("felt") / "fits"
    proc = cs.run("fit", path, "-m", "lambert+ts", "--uncertainty", "mcmc", "--mcmc-steps", "300",
                  "--no-plots", "--out", out, columns=100, timeout=600)  # fmt: skip
    return proc, out


def test_mcmc_intervals_hold_the_optimum_and_walkers_start_over_the_box(felt):
    proc, out = felt
    cs.assert_clean(proc)
    rec = json.loads((out / "lambert+ts.json").read_text())
    assert _inside(rec) == []
    d = rec["uncertainty"]["diagnostics"]
    assert d["likelihood"] == "loss, residual variance marginalized"  # ALTA: no sigma
    assert d["burnt_in"] and d["n_burn"] >= 200
    assert not any("outside the MCMC" in w for w in rec["warnings"])
    assert "lambert+ts: fitted parameters, 95 % intervals (mcmc)" in proc.stdout


def _files():
    out = []
    for sub, pattern in (("rgl", "*.bsdf"), ("cornell", "*.brdf"), ("alta", "*.alta"),
                         ("alta", "*.dat")):  # fmt: skip
        out += sorted(str(p) for p in (SHARED_DATA / sub).glob(pattern))
    zip_ = SHARED_DATA / "nbrdf" / "merl_nbrdf.zip"
    names = ("chrome-steel", "gold-metallic-paint2", "blue-metallic-paint2", "red-fabric2",
             "white-diffuse-bball", "red-specular-plastic")  # fmt: skip
    out += [f"{zip_}::{m}" for m in names]
    # the sampler finds a needle-lobe mode there that scores better than the optimum the
    # optimizer keeps (it rejects needles as degenerate); see benchmarks/README.md
    needle = pytest.mark.xfail(reason="posterior mode is a needle lobe the optimizer rejects")
    return [pytest.param(p, marks=needle) if p.endswith("white-diffuse-bball") else p
            for p in out]  # fmt: skip


@pytest.mark.slow
@pytest.mark.parametrize("path", _files(), ids=lambda p: str(p).rpartition("/")[2])
def test_mcmc_agrees_with_the_optimizer_on_real_files(path):
    import gonio.fit as gf

    shared_file(*path.split("::")[0].rpartition("data/")[2].split("/"))
    r = gf.fit(path, "lambert+ts", uncertainty="mcmc")
    rec = json.loads(json.dumps(r.to_json()))
    assert _inside(rec) == [], r.uncertainty.warnings
