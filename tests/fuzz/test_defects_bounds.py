"""Defects of the second hostile-files round (issue #45) outside the RGL and fit-JSON readers,
one constructed input each, run through the ``gonio`` console script where the issue showed
them there: memory bounded by what the input means (checked before allocating), one line on
stderr and a non-zero exit for input that cannot be right, never a traceback."""

from __future__ import annotations

import json
import re
import struct
from pathlib import Path

import numpy as np
import pytest

from gonio import io
from gonio.errors import FormatError
from tests import console_script
from tests.fuzz.corpus import _half_diff_table


def _one_line_refusal(proc, path: Path, match: str) -> None:
    assert proc.returncode != 0 and "Traceback" not in proc.stderr, proc.stderr[-800:]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gonio: ") and str(path.name) in lines[0], lines
    assert re.search(match, lines[0]), lines[0]


def _refused(path: Path, match: str) -> None:
    with pytest.raises(FormatError, match=match) as info:
        io.load(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


# ------------------------------------------------------------------------------------- MERL
def _merl(path: Path, dims: tuple[int, int, int], fill: float = 0.5) -> Path:
    n = int(np.prod(dims))
    path.write_bytes(struct.pack("<3i", *dims) + np.full(3 * n, fill, "<f8").tobytes())
    return path


def test_merl_grid_beyond_a_measured_grid_is_refused_from_its_header(tmp_path):
    """1.5 MB declaring 1 x 1 x 65536 cells: ``gonio convert T.binary out.exr`` reached 3.0
    GiB writing 65,536 one-cell slices. Each axis is bounded at 4 times MERL's resolution."""
    p = _merl(tmp_path / "T.binary", (1, 1, 65536))
    assert p.stat().st_size < 2 << 20
    proc = console_script.run("convert", p, tmp_path / "out.exr")
    _one_line_refusal(proc, p, r"MERL dimensions \(1, 1, 65536\) beyond .* \(360, 360, 720\)")
    assert not (tmp_path / "out.exr").exists()
    # within each axis' bound, over the cells' one: refused from the header alone
    q = tmp_path / "cells.binary"
    q.write_bytes(struct.pack("<3i", 360, 360, 46))
    _refused(q, r"5832000 in all")
    _merl(q, (360, 360, 46))
    _refused(q, r"more than the 139968012 a file of this kind may have")  # before reading


def test_merl_grid_at_the_bounds_loads(tmp_path):
    from gonio.io.merl import MAX_DIMS

    t = io.load(_merl(tmp_path / "thin.binary", (1, 1, MAX_DIMS[2])))
    assert t.values.shape == (1, 1, 720, 3) and bool(np.all(t.mask))


def test_merl_file_with_a_negated_channel_is_refused(tmp_path):
    """Negative values mark unmeasured cells, in all three channels; a red channel negated
    everywhere left the cells where red was exactly 0 (or an invalid -1, now +1) and loaded
    without a word."""
    p = tmp_path / "neg.binary"
    io.save(_half_diff_table((5, 5, 10), 8), p)
    d = p.read_bytes()
    raw = np.frombuffer(d, "<f8", offset=12).copy().reshape(3, -1)
    assert np.array_equal(raw[0] < 0, raw[1] < 0)  # the writer marks all three channels
    raw[0] = -raw[0]
    p.write_bytes(d[:12] + raw.tobytes())
    _refused(p, r"MERL channel R is negative at \d+ of the \d+ cells the other channels measured")
    raw[0, :] = np.abs(raw[0])
    raw[0, ::1000] = -1.0  # a few cells marked in one channel only: kept as invalid cells
    p.write_bytes(d[:12] + raw.tobytes())
    t = io.load(p)
    assert 0 < np.count_nonzero(t.mask) < t.mask.size


# -------------------------------------------------------------------------- Cornell, ALTA
def _zeros_text(path: Path, header: str, line: str, mib: int = 63) -> Path:
    with open(path, "w") as fh:
        fh.write(header)
        block = line * 4096
        while fh.tell() < mib << 20:
            fh.write(block)
    return path


@pytest.mark.parametrize(
    "name, header, line",
    [
        ("zeros.alta", "#DIM 3 1\n#PARAM_IN ISOTROPIC_TL_TV_PROJ_DPHI\n", "0 0 0 0\n"),
        ("zeros.brdf", "1\n500\n", "0 0 0 0 0\n"),
    ],
)
def test_text_file_of_many_rows_is_refused_before_its_numbers_are_stored(
    tmp_path, name, header, line
):
    """``gonio info`` of 63 MiB of zeros (8 M rows) reached 2.6 GiB (ALTA) and 2.0 GiB
    (Cornell) as Python lists; rows are now counted first (at most 2,097,152)."""
    p = _zeros_text(tmp_path / name, header, line)
    proc, peak = console_script.run_measuring_peak("info", p, tmp_path=tmp_path)
    _one_line_refusal(proc, p, r"lines of text, more than 2097152")
    assert peak < 1 << 30, f"{peak / 2**30:.2f} GiB"


def test_text_file_with_one_huge_line_is_refused(tmp_path):
    """The numbers of a Cornell file may wrap anywhere; one line of 63 MiB is still bounded."""
    p = tmp_path / "long.brdf"
    p.write_text("1\n500\n" + "0 " * (1 << 20) + "\n")
    _refused(p, r"line 3: more than 65536 characters")


def test_many_numbers_on_short_lines_are_refused(tmp_path):
    """Under the line bound, over the numbers' bound (16,777,216: 128 MiB as float64)."""
    p = tmp_path / "wide.alta"
    row = " ".join(["0"] * 20) + "\n"
    # a legal #DIM header; 1.4 M rows of 20 numbers are 29 M numbers
    _zeros_text(p, "#DIM 1 19\n#PARAM_IN COS_TH\n", row, mib=55)
    _refused(p, r"more than 16777216 numbers")


def _alta(tmp: Path, param_in: str, rows: list[list[float]], n_out: int = 1) -> Path:
    from gonio.io.alta import PARAM_IN_DIMS

    p = tmp / f"{param_in.lower()}.alta"
    head = f"#DIM {PARAM_IN_DIMS[param_in]} {n_out}\n#PARAM_IN {param_in}\n"
    head += "#PARAM_OUT INV_STERADIAN\n"
    p.write_text(head + "".join(" ".join(map(str, r)) + "\n" for r in rows))
    return p


GOOD = {
    "ISOTROPIC_TL_TV_PROJ_DPHI": [0.3, 0.2, 0.1, 0.5],
    "ISOTROPIC_TV_TL_DPHI": [0.3, 0.2, 1.0, 0.5],
    "SPHERICAL_TL_PL_TV_PV": [0.3, 1.0, 0.2, -2.0, 0.5],
    "RUSIN_TH_TD_PD": [0.3, 0.2, 1.0, 0.5],
    "RUSIN_TH_PH_TD_PD": [0.3, 0.1, 0.2, 1.0, 0.5],
    "CARTESIAN": [0.0, 0.6, 0.8, 0.6, 0.0, 0.8, 0.5],
}
BAD = [
    ("ISOTROPIC_TL_TV_PROJ_DPHI", 0, 7.0, "polar angle"),  # theta_l in degrees-ish: wrapped
    ("ISOTROPIC_TL_TV_PROJ_DPHI", 1, 40.0, "projected polar angle"),
    ("ISOTROPIC_TV_TL_DPHI", 1, -0.5, "polar angle"),
    ("ISOTROPIC_TV_TL_DPHI", 2, 90.0, "azimuth"),
    ("SPHERICAL_TL_PL_TV_PV", 2, 20.0, "polar angle"),
    ("SPHERICAL_TL_PL_TV_PV", 3, 1e300, "azimuth"),
    ("RUSIN_TH_TD_PD", 2, 180.0, "azimuth"),
    ("RUSIN_TH_PH_TD_PD", 1, -90.0, "azimuth"),
    ("CARTESIAN", 0, 0.0, "unit vector"),  # with 0, 0.6, 0.8 -> length 1 still: see below
    ("CARTESIAN", 3, 5.0, "unit vector"),
]


@pytest.mark.parametrize("param_in, col, value, what", BAD)
def test_alta_angles_outside_their_domain_are_refused(tmp_path, param_in, col, value, what):
    """Commit 69e6b84 bounded COS_TH and the Rusinkiewicz elevations; the spherical
    parametrizations, the azimuths and the Cartesian vectors were still wrapped or
    normalized silently."""
    good = GOOD[param_in]
    assert io.load(_alta(tmp_path, param_in, [good])).values.shape == (1, 1)
    row = list(good)
    row[col] = value
    if param_in == "CARTESIAN" and value == 0.0:
        row[0:3] = [0.0, 0.0, 0.0]  # a zero vector: normalized to NaN, dropped silently
    _refused(_alta(tmp_path, param_in, [good, row]), rf"data row 2: {param_in} input .* {what}")


# ------------------------------------------------------------------------------ TOML input
@pytest.mark.parametrize("what", ["plan", "rig"])
def test_integer_of_more_than_4300_digits_is_one_line(tmp_path, what):
    """``gonio plan --plan P.toml`` with an integer of 5,000 digits: tomllib's int() raised
    ValueError (Python's digit limit) through the CLI as a traceback."""
    huge = "9" * 5000
    if what == "plan":
        p = tmp_path / "P.toml"
        p.write_text(
            f'kind = "isotropic"\ntheta_i_deg = [20, {huge}]\ntheta_o_deg = [20, 50]\n'
            "dphi_deg = [90, 180]\n"
        )
        args = ["plan", "--plan", p]
    else:
        import gonio.rigs

        p = tmp_path / "R.toml"
        rig = (Path(gonio.rigs.__file__).parent / "sim.toml").read_text()
        p.write_text(f"fuzz_count = {huge}\n{rig}")
        args = ["plan", "--rig", p, "--plan", "iso-tiny"]
    proc = console_script.run(*args)
    _one_line_refusal(proc, p, r"invalid TOML: an integer of more than 4300 digits")


# ------------------------------------------------------------------------------ strict JSON
def _strict(text: str):
    def refuse(token: str):
        raise ValueError(f"non-strict JSON token {token}")

    return json.loads(text, parse_constant=refuse)


def test_info_json_prints_strict_json_for_a_nan_in_the_provenance(tmp_path):
    """``gonio info X.brdf.h5 --json`` printed the token ``NaN`` (not JSON) for a NaN in the
    file's metadata attribute; it now prints null and says where and why."""
    import h5py

    p = tmp_path / "x.brdf.h5"
    io.save(_half_diff_table((6, 6, 12), 1), p)
    with h5py.File(p, "r+") as h5:
        h5.attrs["metadata"] = '{"source": {"format": "lab", "gain": NaN, "peak": [1.0, Infinity]}}'
    proc = console_script.run("info", p, "--json")
    console_script.assert_clean(proc)
    out = _strict(proc.stdout)
    assert out["provenance"]["source"]["gain"] is None
    assert out["nonfinite_as_null"] == {
        "provenance.source.gain": "NaN",
        "provenance.source.peak[1]": "Infinity",
    }
    proc = console_script.run("info", p)  # the table prints the same JSON
    console_script.assert_clean(proc)
    assert ": NaN" not in proc.stdout and '"gain": null' in proc.stdout


def test_dumps_json_is_strict():
    from gonio.io.strict_json import dumps_json

    assert _strict(dumps_json([1.0, float("nan")])) == [1.0, None]
    assert _strict(dumps_json({"a": {"b": float("-inf")}, "c": (2, 3)})) == {
        "a": {"b": None},
        "c": [2, 3],
        "nonfinite_as_null": {"a.b": "-Infinity"},
    }
    assert dumps_json({"a": 1}, indent=2) == json.dumps({"a": 1}, indent=2)


def test_run_log_is_strict_json_and_its_reader_takes_null(tmp_path):
    """``RUN/log.jsonl`` wrote ``NaN`` for a non-finite figure; ``gonio plan --timing-from RUN``
    reads the null it writes now as a missing figure."""
    from gonio.acquire.engine import RunLog
    from gonio.acquire.timing import costs_from_run

    log = RunLog(tmp_path / "log.jsonl")
    log("sample", t_capture=2.0, t_book=0.5, move_wall_s=float("nan"), profile_wall_s=0.25)
    log.close()
    (line,) = (tmp_path / "log.jsonl").read_text().splitlines()
    e = _strict(line)
    assert e["move_wall_s"] is None and e["nonfinite_as_null"] == {"move_wall_s": "NaN"}
    costs = costs_from_run(tmp_path)
    assert costs.capture_s == 2.0 and costs.book_s == 0.5 and costs.move_overhead_s == 0.0


# ------------------------------------------------------------------------- channel counts
def _cornell(path: Path, n_wl: int, rows: int = 20) -> Path:
    rng = np.random.default_rng(0)
    lines = [str(n_wl), " ".join(f"{w:.3f}" for w in np.linspace(380, 780, n_wl))]
    for _ in range(rows):
        lines.append(" ".join(f"{x:.4g}" for x in (0.5, 0.1, 0.6, 2.0, *rng.uniform(0.1, 1, n_wl))))
    path.write_text("\n".join(lines) + "\n")
    return path


def test_wavelength_count_is_bounded_before_a_fit(tmp_path):
    """``gonio fit`` on a 300 kB Cornell file of 2,000 wavelengths and 20 samples ran for
    minutes and reached 16 GiB; every reader now bounds the channel count at 128 (the RGL
    reader's bound), on the declared count, and the native writer refuses what its reader
    would."""
    from gonio.brdf.measured import MeasuredSamples
    from gonio.brdf.tabulated import Channels

    p = _cornell(tmp_path / "wide.brdf", 2000)
    proc = console_script.run("fit", p, "--out", tmp_path / "fit")
    _one_line_refusal(proc, p, r"2000 wavelengths, more than the 128 a table may hold")
    assert not (tmp_path / "fit").exists()
    q = tmp_path / "wide.alta"
    q.write_text("#DIM 3 129\n#PARAM_IN ISOTROPIC_TL_TV_PROJ_DPHI\n" + "0.1 0.2 0.3" + " 1" * 129)
    _refused(q, r"129 outputs \(channels\) on #DIM \(line 1\), more than the 128")
    assert io.load(_cornell(tmp_path / "ok.brdf", 128, rows=3)).n_channels == 128
    s = io.load(_cornell(tmp_path / "small.brdf", 4, rows=3))
    wide = MeasuredSamples(wi=s.wi, wo=s.wo, values=np.ones((3, 129)),
                           channels=Channels.spectral(np.linspace(400, 700, 129)))  # fmt: skip
    with pytest.raises(FormatError, match=r"w.brdf.h5: 129 channels, more than the 128"):
        io.save(wide, tmp_path / "w.brdf.h5")
    assert not (tmp_path / "w.brdf.h5").exists()
