"""Neural BRDFs in a zip: the forward pass against a hand-written one, the MERL grid, bad input.

The reference values here are computed from the archive's members with zipfile + h5py and
plain loops, and the directions from gonio.brdf.frames (not from gonio.io.nbrdf's own code).
"""

from __future__ import annotations

import io as pyio
import json
import math
import zipfile

import h5py
import numpy as np
import pytest

from gonio.brdf.frames import half_diff_to_directions
from gonio.cli import main
from gonio.errors import FormatError
from gonio.io import detect_format, load, merl
from gonio.io.nbrdf import NBRDFArchive, list_materials, read_nbrdf
from tests.conftest import shared_file


def _zip():
    return shared_file("nbrdf", "merl_nbrdf.zip")


def _hand_weights(name: str) -> list[tuple[np.ndarray, np.ndarray]]:
    with zipfile.ZipFile(_zip()) as zf:
        data = zf.read(f"merl_nbrdf/{name}.h5")
    layers = []
    with h5py.File(pyio.BytesIO(data), "r") as h5:
        for i in (1, 2, 3):
            g = h5[f"dense_{i}"][f"dense_{i}"]
            layers.append((np.array(g["kernel:0"]), np.array(g["bias:0"])))
    return layers


def _hand_forward(layers, th, td, pd) -> list[float]:
    """The README's convention, written out for one query with explicit sums."""
    x = [math.sin(th), 0.0, math.cos(th)]
    x += [math.sin(td) * math.cos(pd), math.sin(td) * math.sin(pd), math.cos(td)]
    for li, (k, b) in enumerate(layers):
        y = [float(b[j]) + sum(x[i] * float(k[i, j]) for i in range(len(x))) for j in range(len(b))]
        x = [max(v, 0.0) for v in y] if li < len(layers) - 1 else y
    return [math.expm1(v) for v in x]


@pytest.mark.parametrize("name", ["gold-paint", "blue-acrylic", "white-fabric"])
def test_forward_pass_matches_a_hand_written_one(name):
    net = read_nbrdf(f"{_zip()}::{name}")
    layers = _hand_weights(name)
    angles = [(0.02, 0.1, 0.3), (0.4, 0.7, 1.9), (1.0, 0.3, 2.8), (0.15, 1.2, 0.05)]
    for th, td, pd in angles:
        wi, wo = half_diff_to_directions(th, 0.7, td, pd)  # any phi_h: the network ignores it
        got = net.f(np.asarray(wi), np.asarray(wo))
        want = _hand_forward(layers, th, td, pd)
        np.testing.assert_allclose(got, want, rtol=2e-5, atol=1e-7)


def test_table_is_the_network_on_merl_nodes_and_reads_like_merl():
    t = load(f"{_zip()}::gold-paint")
    assert [a.size for a in t.axes] == [90, 90, 180]
    for a, b in zip(t.axes, merl.merl_axes(), strict=True):
        assert (a.name, a.warp, a.node_offset) == (b.name, b.warp, b.node_offset)
    assert t.meta["name"] == "gold-paint"
    net = read_nbrdf(_zip(), "gold-paint")
    layers = _hand_weights("gold-paint")
    vals = np.asarray(t.values)
    for ih, id_, ip in [(0, 0, 0), (10, 40, 90), (60, 20, 170), (89, 5, 3)]:
        th, td, pd = (ih / 90) ** 2 * math.pi / 2, id_ / 90 * math.pi / 2, ip / 180 * math.pi
        wi, wo = (np.asarray(v) for v in half_diff_to_directions(th, 0.0, td, pd))
        valid = wi[2] > 0 and wo[2] > 0
        assert bool(np.asarray(t.mask)[ih, id_, ip]) == valid
        if valid:
            np.testing.assert_allclose(vals[ih, id_, ip], _hand_forward(layers, th, td, pd),
                                       rtol=2e-5, atol=1e-7)  # fmt: skip
            # both are float32 evaluations of one network, but the table's is one XLA program
            # over the grid and this one a single row: summation order differs, and expm1 of the
            # log1p output amplifies it (16 float32 ulps seen on one CI machine)
            np.testing.assert_allclose(vals[ih, id_, ip], net.f(wi, wo), rtol=1e-5)


@pytest.mark.parametrize("name", ["gold-paint", "blue-acrylic", "chrome-steel", "white-fabric"])
def test_values_are_non_negative_and_nearly_reciprocal(name):
    net = read_nbrdf(_zip(), name)
    rng = np.random.default_rng(1)
    th = np.arccos(rng.uniform(0.2, 1.0, (2, 4000)))  # both polar angles below 78 deg
    ph = rng.uniform(0, 2 * np.pi, (2, 4000))
    w = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    a, b = net.f(w[0], w[1], negative="keep"), net.f(w[1], w[0], negative="keep")
    # only the expm1 of small negative outputs, in the dark off-specular cells of metals
    assert np.all(a > -5e-3), a.min()
    assert np.mean(a < 0) < 0.5
    np.testing.assert_array_equal(net.f(w[0], w[1]), np.maximum(a, 0.0))  # clamped by default
    # the network is not constrained to be reciprocal, but it learnt a reciprocal table: the
    # swap changes the value by a few percent of the value (weighted by the value: near-zero
    # off-specular cells of metals have large relative but negligible absolute changes)
    rel = np.sum(np.abs(a - b)) / np.sum(np.abs(a) + np.abs(b))
    assert rel < 0.05, rel
    assert np.all(net.f(w[0] * [1, 1, -1], w[1]) == 0)  # below the horizon


def test_archive_lists_every_complete_material():
    names = list_materials(_zip())
    assert len(names) == 88 and "gold-paint" in names
    assert all(n == n.strip() and "/" not in n for n in names)


def test_convert_writes_a_merl_file_equal_to_the_table(tmp_path):
    out = tmp_path / "gold.binary"
    assert main(["convert", f"{_zip()}::gold-paint", str(out), "--quiet"]) == 0
    back = merl.read_merl_arrays(out)
    t = load(f"{_zip()}::gold-paint")
    m = np.asarray(t.mask)
    assert np.array_equal(back.mask, m)
    np.testing.assert_allclose(back.values[m], np.asarray(t.values)[m], rtol=1e-6)


def _write_zip(path, members: dict[str, bytes]) -> None:
    with zipfile.ZipFile(path, "w") as zf:
        for k, v in members.items():
            zf.writestr(k, v)


def _h5_bytes(shapes, last_bias: float = 0.0) -> bytes:
    buf = pyio.BytesIO()
    with h5py.File(buf, "w") as h5:
        for i, (k, b) in enumerate(shapes, start=1):
            g = h5.create_group(f"dense_{i}")
            g.attrs["weight_names"] = [f"dense_{i}/kernel:0".encode(), f"dense_{i}/bias:0".encode()]
            sub = g.create_group(f"dense_{i}")
            sub["kernel:0"] = np.full(k, 0.01, np.float32)
            sub["bias:0"] = np.full(b, last_bias if i == len(shapes) else 0.0, np.float32)
    return buf.getvalue()


def _desc(units=(4, 3), layer="Dense") -> bytes:
    layers = [
        {"class_name": layer, "config": {"name": f"dense_{i}", "units": u, "activation": act}}
        for i, u in enumerate(units, start=1)
        for act in ["relu" if i < len(units) else "linear"]
    ]
    return json.dumps({"class_name": "Sequential", "config": {"layers": layers}}).encode()


def test_a_small_synthetic_network_evaluates(tmp_path):
    p = tmp_path / "a.zip"
    _write_zip(p, {"x/m.json": _desc(), "x/m.h5": _h5_bytes([((6, 4), 4), ((4, 3), 3)])})
    net = read_nbrdf(f"{p}::m")
    # every weight 0.01, biases 0: hidden = 0.01 * sum(features) (>0), output = 0.04 * that
    wi = np.array([0.0, 0.0, 1.0])
    s = 0.0 + 0 + 1 + 0 + 0 + 1  # theta_h = theta_d = 0
    np.testing.assert_allclose(net.f(wi, wi), [math.expm1(4 * 0.01 * 0.01 * s)] * 3, rtol=1e-5)


def test_negative_outputs_are_clamped_and_counted_as_the_authors_decoder_does():
    """beige-fabric's network is below 0 in some valid cells (down to -0.097, 17 % of its peak):
    clamped at 0 by default, with the count in the provenance; refused in one line on request."""
    t = load(f"{_zip()}::beige-fabric")
    src = t.meta["source"]
    net = read_nbrdf(_zip(), "beige-fabric")
    raw = net.to_table(dims=(30, 30, 60), negative="clamp").meta["source"]
    assert raw["clamped_values"] >= raw["clamped_cells"] > 0  # also on a coarser grid
    m = np.asarray(t.mask)
    vals = np.asarray(t.values)
    assert np.all(vals[m] >= 0)
    assert src["negative"] == "clamp" and src["lowest_output"] < -0.05
    # the clamped cells are exactly those where the hand-written forward pass is negative
    layers = _hand_weights("beige-fabric")
    zero = np.argwhere(m & np.any(vals == 0, axis=-1))
    assert len(zero) >= src["clamped_cells"] > 50
    for ih, id_, ip in zero[:: max(1, len(zero) // 12)]:
        th, td, pd = (ih / 90) ** 2 * math.pi / 2, id_ / 90 * math.pi / 2, ip / 180 * math.pi
        want = np.asarray(_hand_forward(layers, th, td, pd))
        np.testing.assert_allclose(vals[ih, id_, ip], np.maximum(want, 0), rtol=2e-5, atol=1e-6)
    # the count travels into a fit's record of its data
    from gonio.fit.data import prepare

    assert prepare(t).describe()["source"]["clamped_cells"] == src["clamped_cells"]
    with pytest.raises(FormatError) as e:
        load(f"{_zip()}::beige-fabric", negative="keep")
    assert "negative value(s)" in str(e.value) and "\n" not in str(e.value)
    # a network without negative outputs is unchanged by the policy
    g = load(f"{_zip()}::gold-paint")
    assert g.meta["source"]["clamped_values"] == 0
    np.testing.assert_array_equal(
        np.asarray(g.values), np.asarray(load(f"{_zip()}::gold-paint", negative="keep").values)
    )


@pytest.mark.parametrize(
    "members, needle",
    [
        (None, "not a readable zip"),
        ({"readme.txt": b"x"}, "no neural BRDF"),
        ({"m.json": b"{not json", "m.h5": b"x"}, "not a Keras model description"),
        ({"m.json": _desc(layer="Conv2D"), "m.h5": b"x"}, "unsupported layer"),
        ({"m.json": _desc(), "m.h5": b"not hdf5"}, "not a readable Keras weights file"),
        ({"m.json": _desc(), "m.h5": _h5_bytes([((6, 5), 5), ((5, 3), 3)])}, "expected (6, 4)"),
        ({"m.json": _desc((4, 2)), "m.h5": b"x"}, "ending in 3 outputs"),
        (
            {"m.json": _desc(), "m.h5": _h5_bytes([((6, 4), 4), ((4, 3), 3)], last_bias=-1.0)},
            "nowhere positive",
        ),
    ],
)
def test_bad_archives_give_one_line(tmp_path, members, needle):
    p = tmp_path / "bad.zip"
    if members is None:
        p.write_bytes(b"PK\x03\x04 truncated")
    else:
        _write_zip(p, members)
    with pytest.raises(FormatError) as e:
        load(f"{p}::m")
    assert needle in str(e.value) and "\n" not in str(e.value)


def test_unknown_or_missing_names_give_one_line(tmp_path):
    with pytest.raises(FormatError, match=r"'gold' is not in the archive.*similar: gold-"):
        read_nbrdf(_zip(), "gold")
    with pytest.raises(FormatError, match="name one of its 88 materials"):
        load(_zip())
    with pytest.raises(FormatError, match="no such file"):
        load(tmp_path / "missing.zip::x")
    assert detect_format(f"{_zip()}::gold-paint") == "nbrdf"
    p = tmp_path / "half.zip"
    _write_zip(p, {"m.json": _desc(), "n.json": _desc(), "n.h5": b"x"})
    with pytest.raises(FormatError, match=r"lacks its \.json or \.h5"):
        NBRDFArchive(p).read("m")
