"""The defects the fuzzer found, one constructed input each: a typed one-line error naming the
file (and the field), never a hang, a raw exception, a memory blow-up or a silent load."""

from __future__ import annotations

import json
import struct
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from gonio import io
from gonio.errors import FormatError, PlanError, RigConfigError
from tests.fuzz.corpus import _half_diff_table, _samples

ROOT = Path(__file__).resolve().parents[2]


def _native(tmp: Path, obj, name: str = "t.brdf.h5") -> Path:
    p = tmp / name
    io.save(obj, p)
    return p


def _refused(path: Path, match: str, exc: type = FormatError) -> None:
    with pytest.raises(exc, match=match) as info:
        io.load(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


# ------------------------------------------------------------------------------------ native
def test_global_heap_object_of_size_zero_is_refused_not_looped_on(tmp_path):
    """The 1 KB duplication at offset 1103 of the issue leaves a global heap object with index 0
    and size 0; libhdf5's decoder then loops forever in C. The load runs in a subprocess so that
    a regression fails the test instead of hanging it."""
    p = _native(tmp_path, _samples(50, 1))
    data = bytearray(p.read_bytes())
    at = data.find(b"GCOL\x01")
    assert at > 0
    obj = at + 16 + 2 * 32  # the third object (the first two are 32 bytes each here)
    data[obj : obj + 16] = bytes(16)  # index 0, size 0
    p.write_bytes(bytes(data))
    code = (
        "import sys; from gonio import io; from gonio.errors import FormatError\n"
        f"try: io.load({str(p)!r})\n"
        "except FormatError as e: print(e); sys.exit(0)\n"
        "sys.exit(1)"
    )
    r = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=120,
        env={"PYTHONPATH": str(ROOT / "src"), "JAX_PLATFORMS": "cpu", "PATH": "/usr/bin:/bin"},
    )
    assert r.returncode == 0, r.stderr[-500:]
    assert "global heap" in r.stdout and str(p) in r.stdout


def test_duplicated_kilobyte_in_old_layout_scattered_file(tmp_path):
    """The issue's input itself: 1 KB duplicated at 1103 in a scattered file of the old layout
    (contiguous datasets, no checksums), written here with plain h5py as gonio used to."""
    p = _native(tmp_path, _samples(200, 4))
    src = tmp_path / "old.brdf.h5"
    with h5py.File(p) as a, h5py.File(src, "w", libver=("v108", "v108")) as b:
        for k, v in a.attrs.items():
            b.attrs[k] = v
        a.copy("channels", b)
        for k in ("wi", "wo", "values", "sigma", "weights"):
            ds = b.create_dataset(k, data=a[k][()])
            for ak, av in a[k].attrs.items():
                ds.attrs[ak] = av
    d = src.read_bytes()
    bad = tmp_path / "dup.brdf.h5"
    bad.write_bytes(d[: 1103 + 1024] + d[1103 : 1103 + 1024] + d[1103 + 1024 :])
    r = subprocess.run(
        [sys.executable, "-c", f"from gonio import io; io.load({str(bad)!r})"],
        capture_output=True,
        text=True,
        timeout=120,
        env={"PYTHONPATH": str(ROOT / "src"), "JAX_PLATFORMS": "cpu", "PATH": "/usr/bin:/bin"},
    )
    assert "FormatError" in r.stderr and str(bad) in r.stderr
    assert io.load(src).values.shape == (200, 3)  # the undamaged old-layout file loads


def _replace(path: Path, name: str, **kw) -> None:
    with h5py.File(path, "r+") as h5:
        attrs = dict(h5[name].attrs)
        del h5[name]
        ds = h5.create_dataset(name, **kw)
        for k, v in attrs.items():
            ds.attrs[k] = v


def test_external_storage_and_virtual_datasets_are_refused(tmp_path):
    p = _native(tmp_path, _half_diff_table((6, 6, 12), 1))
    shape = (6, 6, 12, 3)
    _replace(p, "values", shape=shape, dtype="f4", external=[("/dev/zero", 0, 4 * 1296 * 3)])
    _refused(p, "external storage")
    p = _native(tmp_path, _half_diff_table((6, 6, 12), 1), "v.brdf.h5")
    with h5py.File(p, "r+") as h5:
        src = h5.create_dataset("src", data=h5["values"][()])
        layout = h5py.VirtualLayout(shape=shape, dtype="f4")
        layout[...] = h5py.VirtualSource(src)
        attrs = dict(h5["values"].attrs)
        del h5["values"]
        v = h5.create_virtual_dataset("values", layout)
        for k, val in attrs.items():
            v.attrs[k] = val
    _refused(p, "virtual dataset")


def test_declared_huge_grid_with_unallocated_chunks_is_refused_before_allocating(tmp_path):
    """40 KB declaring 256^3 cells: the chunks were never written (they would read as the fill
    value, costing gigabytes); refused from the metadata alone."""
    p = _native(tmp_path, _half_diff_table((6, 6, 12), 1))
    with h5py.File(p, "r+") as h5:
        for ax in ("theta_h", "theta_d", "phi_d"):
            h5["axes"][ax].attrs["size"] = np.int64(256)
        for k in ("sigma", "counts"):
            del h5[k]
    grid = (256, 256, 256)
    _replace(p, "values", shape=(*grid, 3), dtype="f4", chunks=(1, 256, 256, 1))
    _replace(p, "mask", shape=grid, dtype="u1", chunks=(1, 256, 256), fillvalue=1)
    assert p.stat().st_size < 100_000
    _refused(p, "chunks stored")


def test_declared_size_over_the_memory_budget_is_refused(tmp_path):
    p = _native(tmp_path, _samples(100, 2))
    n = 10**8
    for k in ("wi", "wo"):
        _replace(p, k, shape=(n, 3), dtype="f8", chunks=(1 << 16, 3))
    _refused(p, "over the 1024 MiB a file may take")
    p = _native(tmp_path, _samples(100, 2), "s.brdf.h5")  # each under the budget, not together
    for k in ("wi", "wo"):
        _replace(p, k, shape=(3 * 10**7, 3), dtype="f8", chunks=(1 << 20, 3))
    _refused(p, "in total")


def test_filters_outside_the_documented_set_and_expanding_chunks_are_refused(tmp_path, monkeypatch):
    p = _native(tmp_path, _half_diff_table((16, 16, 32), 2))
    v = np.zeros((16, 16, 32, 3), np.float32)
    _replace(p, "values", data=v, chunks=(4, 16, 32, 1), compression="lzf")
    _refused(p, "filter 32000")
    p = _native(tmp_path, _half_diff_table((16, 16, 32), 2), "z.brdf.h5")
    monkeypatch.setattr("gonio.io._hdf5_guard.MAX_COMPRESSION_RATIO", 20)
    _refused(p, "expands")


@pytest.mark.parametrize(
    ("bad", "match"),
    [(np.nan, "NaN/Inf"), (np.inf, "NaN/Inf"), (-1.0, "negative"), (1e38, "beyond any")],
)
def test_values_that_cannot_be_right_are_refused(tmp_path, bad, match):
    p = _native(tmp_path, _half_diff_table((6, 6, 12), 1))
    with h5py.File(p, "r+") as h5:
        v = h5["values"][()]
        v[1, 2, 3, 0] = bad
        h5["values"][...] = v
    _refused(p, match)


def test_small_negative_noise_is_kept(tmp_path):
    """Values down to -1 % of the peak (noise, out-of-gamut colour conversion) still load."""
    t = _half_diff_table((6, 6, 12), 1)
    values = np.asarray(t.values).copy()
    values[0, 0, 0, 2] = -0.005 * values.max()
    p = _native(tmp_path, t.replace(values=values))
    assert float(np.min(io.load(p).values)) < 0


def test_axis_beyond_its_domain_and_no_valid_cell_are_refused(tmp_path):
    p = _native(tmp_path, _half_diff_table((6, 6, 12), 1))
    with h5py.File(p, "r+") as h5:
        h5["axes"]["theta_h"].attrs["hi"] = 100.0
    _refused(p, r"theta_h.*outside \[0, 1.5708")
    p = _native(tmp_path, _half_diff_table((6, 6, 12), 1), "m.brdf.h5")
    with h5py.File(p, "r+") as h5:
        h5["mask"][...] = 0
    _refused(p, "no valid cell")


def test_directions_below_the_horizon_are_refused(tmp_path):
    p = _native(tmp_path, _samples(100, 3))
    with h5py.File(p, "r+") as h5:
        w = h5["wi"][()]
        w[:10, 2] *= -1
        h5["wi"][...] = w
    _refused(p, "10 direction.*below the horizon")


def test_payload_bit_flip_is_caught_by_the_checksum(tmp_path):
    p = _native(tmp_path, _half_diff_table((6, 6, 12), 1))  # small: one uncompressed chunk
    with h5py.File(p) as h5:
        assert h5["values"].fletcher32 and h5["values"].compression is None
        off = h5["values"].id.get_chunk_info(0).byte_offset
    d = bytearray(p.read_bytes())
    d[off + 40] ^= 0x01  # a low mantissa bit: the value would still look plausible
    p.write_bytes(bytes(d))
    _refused(p, "corrupt gonio-brdf file")


def test_files_without_checksums_still_load():
    for name in ("tiny-gridded.brdf.h5", "tiny-scattered.brdf.h5"):
        path = ROOT / "data-schema" / "examples" / name
        with h5py.File(path) as h5:
            assert not h5["values"].fletcher32
        assert io.load(path) is not None


def test_a_reader_looping_over_the_file_stops(tmp_path, monkeypatch):
    p = _native(tmp_path, _half_diff_table((16, 16, 32), 2))
    monkeypatch.setattr("gonio.io._hdf5_guard.MAX_READ_CALLS", 5)
    _refused(p, "HDF5 structures loop")


# ------------------------------------------------------------------------------ other formats
def test_merl_value_overflowing_float32_names_the_file(tmp_path):
    p = tmp_path / "m.binary"
    io.save(_half_diff_table((5, 5, 10), 8), p)
    d = bytearray(p.read_bytes())
    struct.pack_into("<d", d, 12 + 8 * 7, 1e300)
    p.write_bytes(bytes(d))
    _refused(p, "beyond any reflectance")
    d[12:] = np.full((len(d) - 12) // 8, -1.0).tobytes()  # every cell marked invalid
    p.write_bytes(bytes(d))
    _refused(p, "no valid cell")


def test_cornell_and_alta_negative_or_absurd_values_are_refused(tmp_path):
    from tests.fuzz.corpus import _alta_text, _cornell_text

    lines = _cornell_text(5, 1).splitlines()
    rec = lines[4].split()
    for bad, match in (("-1", "negative"), ("1e308", "beyond any")):
        p = tmp_path / f"c{bad}.brdf"
        p.write_text("\n".join([*lines[:4], " ".join([*rec[:5], bad, *rec[6:]]), *lines[5:]]))
        _refused(p, match)
    lines = _alta_text(5, 2).splitlines()
    rec = lines[5].split()
    p = tmp_path / "a.alta"
    p.write_text("\n".join([*lines[:5], " ".join([*rec[:3], "-2", *rec[4:]]), *lines[6:]]))
    _refused(p, "negative")


def test_rgl_field_of_shape_zero_by_two_to_the_63_is_refused(tmp_path):
    from gonio.io.rgl import read_rgl, tensor_file_bytes

    d = bytearray(tensor_file_bytes({"a": np.zeros((0, 3), np.float32)}))
    struct.pack_into("<Q", d, 18 + 2 + 1 + 11 + 8, 2**63)  # shape[1] of field "a"
    p = tmp_path / "zero.bsdf"
    p.write_bytes(bytes(d))
    with pytest.raises(FormatError, match="impossible shape") as info:
        read_rgl(p)
    assert str(p) in str(info.value)


@pytest.fixture(scope="module")
def rgl_fields(tmp_path_factory):
    """Fields of a small RGL file written by gonio's writer (Lambert + rough Torrance-Sparrow)."""
    from gonio.brdf import models
    from gonio.io.rgl import read_rgl

    p = tmp_path_factory.mktemp("rgl") / "written.bsdf"
    io.save(models.Lambert(albedo=[0.5, 0.35, 0.2]) + models.TorranceSparrow(alpha=0.3), p)
    return dict(read_rgl(p).fields)


def test_rgl_sign_flipped_colour_table_is_refused(tmp_path, rgl_fields):
    """A colour payload with every value negated (fuzz "payload negate") loaded as a BSDF whose
    ``f`` is negative everywhere; gamut-noise negatives of a few % of the peak still load."""
    from gonio.io.rgl import tensor_file_bytes

    fields = dict(rgl_fields)
    fields["rgb"] = -np.abs(fields["rgb"])
    p = tmp_path / "negated.bsdf"
    p.write_bytes(tensor_file_bytes(fields))
    _refused(p, "field 'rgb' is clearly negative")
    rgb = fields["rgb"] = np.abs(rgl_fields["rgb"]).copy()
    rgb.reshape(-1)[::7] = -0.03 * float(rgb.max())  # as the vinyl films of the database
    p.write_bytes(tensor_file_bytes(fields))
    b = io.load(p)
    w = np.array([[0.3, 0.0, 0.954]]) / np.linalg.norm([0.3, 0.0, 0.954])
    assert np.all(np.isfinite(np.asarray(b.f(w, w))))


# ------------------------------------------------------------------------------- fit results
@pytest.fixture(scope="module")
def fit_json(tmp_path_factory):
    from tests.fuzz.corpus import _fit_json

    return json.loads(_fit_json(tmp_path_factory.mktemp("fit"))[0].path.read_text())


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda o: b'{"x": "\xff"}', "not UTF-8"),
        (lambda o: b"[" * 5000 + b"]" * 5000, "nested deeper"),
        (lambda o: json.dumps(o).replace('"loss": ', '"loss": NaN, "x": ').encode(), "NaN"),
        (lambda o: json.dumps(o).replace('"loss": ', '"loss": 1e999, "x": ').encode(), "overflow"),
        (lambda o: _spec(o, params=[1, 2]), "params is not an object"),
        (lambda o: _spec(o, params={}), "'albedo' of Lambert is missing"),
        (lambda o: _spec(o, params={"albedo": None}), "'albedo' of Lambert is missing or null"),
        (lambda o: _spec(o, params={"albedo": "x"}), "not a finite number"),
        (lambda o: _spec(o, children={"x": {}}), "unknown children"),
        (lambda o: _spec(o, type="Nope"), "unknown model type"),
    ],
)
def test_fit_results_that_cannot_be_right_are_refused(tmp_path, fit_json, edit, match):
    from gonio.io.fit_result import load_model

    p = tmp_path / "fit.json"
    p.write_bytes(edit(fit_json))
    with pytest.raises(FormatError, match=match) as info:
        load_model(p)
    assert str(p) in str(info.value)


def _spec(obj: dict, **change) -> bytes:
    o = json.loads(json.dumps(obj))
    o["model_spec"].update(change)
    return json.dumps(o).encode()


# ------------------------------------------------------------------------------ plans and rigs
@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("kind = ['isotropic']", "kind"),
        ("x = " + "[" * 600 + "]" * 600, "nested deeper"),
        (
            "kind = 'isotropic'\ntheta_i_deg = [10]\ntheta_o_deg = [10]\n"
            "dphi_deg = { start = 0, stop = 180, step = 1e-300 }",
            "more than 3600",
        ),
        (
            "kind = 'grid4d'\ntheta_i_deg = { start = 0, stop = 90, step = 0.1 }\n"
            "phi_i_deg = { start = 0, stop = 359, step = 0.5 }\ntheta_o_deg = [10]\n"
            "phi_o_deg = [0]",
            "more than 10000",
        ),
        ("kind = 'isotropic'\ntheta_i_deg = [10]\ntheta_o_deg = [10]\ndphi_deg = [nan]", "finite"),
        (
            "kind = 'halfdiff'\ntheta_h_deg = [1]\ntheta_d_deg = { start = 0, stop = 60, "
            "step = 1e-320 }\nphi_d_deg = [90]",
            "more than 3600",
        ),
        (
            "kind = 'isotropic'\ntheta_i_deg = [10]\ntheta_o_deg = [10]\n"
            "dphi_deg = { start = 0, stop = 180, step = true }",
            "numeric",
        ),
    ],
)
def test_plan_files_are_bounded_and_errors_name_the_file(tmp_path, text, match):
    from gonio.acquire.plans import load_plan

    p = tmp_path / "bad.plan.toml"
    p.write_text(text)
    with pytest.raises(PlanError, match=match) as info:
        load_plan(p)
    assert str(p) in str(info.value)


@pytest.mark.parametrize(
    ("old", "new", "match"),
    [
        ("settle_tolerance_deg = 0.3", "settle_tolerance_deg = nan", "settle_tolerance_deg"),
        ("min_deg = -170.0", "min_deg = -inf", r"joints\[0\].min_deg"),
        ("max_deg = 170.0", "max_deg = 1e308", r"rig.toml:\d+: joints\[0\].max_deg.*servo tick"),
        (
            "profile_acceleration_deg_s2 = 180.0",
            "profile_acceleration_deg_s2 = 1e-320",
            r"rig.toml:\d+: joints\[0\].profile_acceleration_deg_s2.*outside 1\.\.32767",
        ),
        ('name = "sim"', "name = " + "[" * 600 + "]" * 600, "nested deeper"),
    ],
)
def test_rig_files_with_nan_inf_or_deep_nesting_are_refused(tmp_path, old, new, match):
    from importlib import resources

    from gonio.rigs.config import load_rig

    text = resources.files("gonio.rigs").joinpath("sim.toml").read_text()
    assert old in text
    p = tmp_path / "rig.toml"
    p.write_text(text.replace(old, new, 1))
    with pytest.raises(RigConfigError, match=match) as info:
        load_rig(p)
    assert str(p) in str(info.value)
