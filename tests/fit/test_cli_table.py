"""Issue 21: the fit table fits 80 columns without cutting a model name or a number, through
the installed console script (COLUMNS=80, output piped) and for the longest preset names."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gonio.brdf import models
from gonio.fit.presets import available
from gonio.fit.table_text import fit_table_lines
from tests import console_script as cs


def _row(name: str, k: int) -> dict:
    return {
        "model": name,
        "n_params": k,
        "loss": 1.234567e5 * k,
        "chi2_dof": 12345.678,
        "bic": -1.2345678e5 - k,
        "delta_bic": 123456.7 * (k - 3),
        "metrics": {"ngan": 1.23456e-5, "low-e1": 0.0456789},
        "flags": [] if k != 7 else ["not converged"],
    }


@pytest.mark.parametrize("width", [80, 100, 300])
def test_every_preset_name_and_number_is_shown_whole(width):
    rows = [_row(name, 3 + i % 9) for i, name in enumerate(available())]
    lines = fit_table_lines(rows, width)
    assert max(len(line) for line in lines) <= width
    text = "\n".join(lines)
    assert "\u2026" not in text
    for r in rows:
        hit = [line for line in lines if line.split() and line.split()[0] == r["model"]]
        assert len(hit) == 1, r["model"]
    stacked = lines[0] == "model"
    assert stacked == (width < 124)  # the longest name (35) and the numbers need 119
    rule = next(j for j, line in enumerate(lines) if set(line) == {"-"})
    groups = rule - 1 if stacked else 1  # header lines of number groups
    heads = [h for line in lines[1:rule] for h in line.split()] if stacked else (
        lines[0].split()[1:])  # fmt: skip
    assert heads == ["params", "loss", "chi2/dof", "BIC", "dBIC", "ngan", "low-e1", "flags"]
    for r in rows:
        i = next(j for j, line in enumerate(lines) if line.split()[:1] == [r["model"]])
        if stacked:
            cells = [c for line in lines[i + 1 : i + 1 + groups] for c in line.split()]
        else:
            cells = lines[i].split()[1:]
        assert int(cells[0]) == r["n_params"]
        got = [float(c) for c in cells[1:7]]
        want = [r["loss"], r["chi2_dof"], r["bic"], r["delta_bic"],
                r["metrics"]["ngan"], r["metrics"]["low-e1"]]  # fmt: skip
        assert got == pytest.approx(want, rel=1e-2, abs=0.06)
        assert cells[7] == ("-" if not r["flags"] else "no-conv")


def test_a_narrow_terminal_puts_the_numbers_on_more_lines():
    lines = fit_table_lines([_row("lambert+cook-torrance+cook-torrance", 11)], 50)
    assert max(len(line) for line in lines) <= 50
    assert lines[0] == "model" and "lambert+cook-torrance+cook-torrance" in lines
    assert len(lines) > 4  # two header lines of numbers, two number lines


def test_rows_without_sigma_show_no_chi_square_and_rank_by_the_measured_loss():
    rows = [{k: v for k, v in _row(n, k).items() if k not in ("chi2_dof", "bic", "delta_bic")}
            for n, k in (("lambert", 3), ("lambert+ts", 7))]  # fmt: skip
    rows[0]["delta_rank"], rows[1]["delta_rank"] = 0.0, 0.25
    lines = fit_table_lines(rows, 100)
    assert lines[0].split() == ["model", "params", "loss", "vs", "best", "ngan", "low-e1", "flags"]
    assert lines[2].split()[3] == "+0.0%" and lines[3].split()[3] == "+25.0%"
    rows[0]["appearance"] = {"hdr_flip": 0.125, "rel_l1": 0.25}  # once rows carry the score
    assert fit_table_lines(rows, 120)[0].split() == [
        "model", "params", "loss", "flip", "relL1", "vs", "best", "ngan", "low-e1", "flags"
    ]  # fmt: skip


def test_fit_table_at_80_columns_through_the_console_script(tmp_path):
    gio = pytest.importorskip("gonio.io")
    from gonio.brdf.tabulated import Axis, TabulatedBRDF

    axes = (
        Axis("theta_h", 12, 0, np.pi / 2, warp="sqrt"),
        Axis("theta_d", 12, 0, np.pi / 2),
        Axis("phi_d", 12, 0, np.pi, periodic=True),
    )
    path = tmp_path / "mat.brdf.h5"
    gio.save(TabulatedBRDF.from_model(models.Phong(rho_d=[0.2] * 3, rho_s=0.3, n=40.0), axes), path)
    out = tmp_path / "fits"
    proc = cs.run("fit", path, "-m", "lambert", "-m", "phong", "-m", "lambert+ts-ggx-smith",
                  "--uncertainty", "none", "--no-plots", "--out", out, columns=80)  # fmt: skip
    cs.assert_clean(proc)
    lines = proc.stdout.splitlines()
    assert max(len(line) for line in lines) <= 80, proc.stdout
    assert "\u2026" not in proc.stdout
    table = json.loads((out / "summary.json").read_text())["table"]
    for r in table:
        i = next(j for j, line in enumerate(lines) if line.split()[:1] == [r["model"]])
        cells = lines[i].split()[1:] or lines[i + 1].split()  # the name whole
        assert int(cells[0]) == r["n_params"]
        assert float(cells[1]) == pytest.approx(r["loss"], rel=1e-3)
        assert "bic" not in r and "chi2_dof" not in r  # a table without sigma: no chi-square
    assert "recommended: phong" in proc.stdout
