"""Building a prior from tables, its file, and bad files."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from gonio.errors import FormatError, ParameterError
from gonio.prior import Prior, build_prior, space
from tests.prior.conftest import SMALL_AXES


@pytest.fixture(scope="module")
def built(tables):
    return build_prior(tables, [f"m{i}" for i in range(6)], axes=SMALL_AXES), tables


def test_build_basis_variances_and_rank_rule(built):
    prior, tables = built
    K = prior.rank
    B = prior.basis.reshape(-1, K).astype(np.float64)
    np.testing.assert_allclose(B.T @ B, np.eye(K), atol=1e-4)
    assert (np.diff(prior.variances) <= 0).all() and (prior.variances > 0).all()
    loo = prior.meta["rank_selection"]["loo_rms"]
    assert len(loo) == 4 and K <= 4  # up to M - 2
    assert loo[K - 1] <= min(loo) * 1.02 + 1e-12
    # a training material is reproduced by its projection better than the held-out error
    wi, wo = prior.cell_directions()
    m = space.to_mapped(np.asarray(tables[0].f(wi, wo), np.float64), space.cos_product(wi, wo))
    c = B.T @ (m - prior.mean).reshape(-1)
    resid = (m - prior.mean).reshape(-1) - B @ c
    assert np.sqrt(np.mean(resid**2)) < loo[K - 1]
    with pytest.raises(ParameterError, match="at least 3"):
        build_prior(tables[:2], ["a", "b"], axes=SMALL_AXES)


def test_file_round_trip(built, tmp_path):
    prior, _ = built
    path = tmp_path / "p.prior.h5"
    prior.write(path)
    back = Prior.read(path)
    assert back.rank == prior.rank and back.meta["materials"] == prior.meta["materials"]
    np.testing.assert_array_equal(back.basis, prior.basis)
    np.testing.assert_allclose(back.mean, prior.mean, rtol=1e-6)
    np.testing.assert_array_equal(back.mask, prior.mask)
    assert back.axes == prior.axes and back.epsilon == prior.epsilon
    assert path.stat().st_size < 100e6


def _copy_with(src, dst, edit):
    import shutil

    shutil.copy(src, dst)
    with h5py.File(dst, "r+") as h5:
        edit(h5)
    return dst


@pytest.mark.parametrize("case", ["nan", "shape", "meta", "format", "text", "truncated"])
def test_bad_files_are_one_line_errors(built, tmp_path, case):
    prior, _ = built
    good = tmp_path / "good.prior.h5"
    prior.write(good)
    bad = tmp_path / "bad.prior.h5"
    if case == "nan":

        def edit(h5):
            h5["variances"][0] = np.nan

        _copy_with(good, bad, edit)
    elif case == "shape":

        def edit(h5):
            del h5["mean"]
            h5["mean"] = np.zeros((3, 3), np.float32)

        _copy_with(good, bad, edit)
    elif case == "meta":
        _copy_with(good, bad, lambda h5: h5.attrs.__setitem__("metadata", '{"rank": 1}'))
    elif case == "format":
        _copy_with(good, bad, lambda h5: h5.attrs.__setitem__("format", "gonio-brdf"))
    elif case == "text":
        bad.write_text("not a prior\n")
    else:
        bad.write_bytes(good.read_bytes()[:4000])
    with pytest.raises(FormatError) as err:
        Prior.read(bad)
    msg = str(err.value)
    assert "\n" not in msg and str(bad) in msg
