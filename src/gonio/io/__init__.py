"""File formats: native ``*.brdf.h5`` tables, MERL, RGL tensor files, Cornell, ALTA, EXR, and
fit results (:mod:`gonio.io.fit_result`, the one reader and writer of ``gonio fit``'s JSON).

>>> from gonio import io
>>> t = io.load("material.binary")          # format detected from the content
>>> io.save(t, "material.brdf.h5")          # format chosen by the extension
"""

from __future__ import annotations

import os
from typing import Any

from gonio.errors import ParameterError
from gonio.io._common import PathLike, fail
from gonio.io.detect import FORMATS, detect_format

__all__ = ["FORMATS", "detect_format", "load", "save"]


def load(
    path: PathLike,
    *,
    color: str | None = None,
    illuminant: str = "D65",
    negative: str | None = None,
    merl_cells: str = "centre",
) -> Any:
    """Load a BRDF file, detecting its format from its content.

    Parameters
    ----------
    path : path-like
        A native ``*.brdf.h5`` file, MERL ``.binary``, RGL ``.bsdf``, Cornell ``.brdf`` or ALTA
        text file, or ``"ARCHIVE.zip::NAME"``: material ``NAME`` of a neural-BRDF archive
        (:mod:`gonio.io.nbrdf`), evaluated on MERL's grid.
    color : {"rgb", "spectral", "keep"}, optional
        For spectral sources (Cornell, spectral RGL files): ``"rgb"`` converts to linear sRGB
        through CIE 1931 XYZ under ``illuminant``; default keeps the spectrum. For
        single-channel ALTA data ``"rgb"`` replicates the channel.
    illuminant : {"D65", "E"}
    negative : {"keep", "clamp"}, optional
        Negative values, as each format's reference reader treats them by default. RGL files:
        keep the file's (few, slightly) negative colour values as Mitsuba does (default), or
        clamp them at 0 (see :mod:`gonio.io.rgl_measured`). Neural BRDFs: clamp negative
        network outputs at 0 as the authors' decoder does (default; counted in
        ``meta["source"]``), or keep the raw output and refuse a network clearly below 0 (see
        :mod:`gonio.io.nbrdf`).
    merl_cells : {"centre", "start"}
        MERL files only: a cell's node (its sample position) at the cell centre in the warped
        index (default; nearest lookup is then the reference reader's cell) or at its lower
        edge (fastmerl / Neural-BRDF); see :mod:`gonio.io.merl`.

    Returns
    -------
    TabulatedBRDF, RGLMeasured or MeasuredSamples
        Gridded formats (native gridded, MERL) give a :class:`TabulatedBRDF`; RGL files give an
        exact :class:`~gonio.io.rgl_measured.RGLMeasured` (the file's own function and warps,
        ``to_table()`` resamples it). Scattered formats (native scattered, Cornell, ALTA) give
        :class:`MeasuredSamples`.

    Raises
    ------
    FormatError
        Malformed, truncated, unknown-version or unrecognized files; one line naming the file.
    """
    fmt = detect_format(path)
    if fmt == "nbrdf":
        from gonio.io.nbrdf import load_nbrdf_table

        return load_nbrdf_table(path, negative=negative or "clamp")
    if fmt == "native":
        from gonio.io.native import read_native

        return read_native(path)
    if fmt == "merl":
        from gonio.io.merl import read_merl

        return read_merl(path, cells=merl_cells)
    if fmt == "rgl":
        from gonio.io.rgl_measured import load_rgl

        return load_rgl(path, negative=negative or "keep", color=color, illuminant=illuminant)
    if fmt == "cornell":
        from gonio.io.cornell import read_cornell

        return read_cornell(
            path, color="rgb" if color == "rgb" else "spectral", illuminant=illuminant
        )
    if fmt == "alta":
        from gonio.io.alta import read_alta

        return read_alta(path, color="rgb" if color == "rgb" else "keep")
    raise fail(path, f"{fmt} files hold images, not BRDF data (see gonio.io.exr)")


def save(obj: Any, path: PathLike, *, lossy: float | None = None) -> None:
    """Save ``obj`` in the format named by the extension of ``path``, atomically.

    An object with ``to_table()`` (e.g. :class:`gonio.io.rgl_measured.RGLMeasured`) is tabulated
    first.
    ``.brdf.h5`` (or ``.h5``): native (``lossy``: guaranteed relative precision, e.g. 0.005);
    ``.binary``: MERL (RGB half/diff tables; others are resampled); ``.exr``: one image per
    ``phi_d`` slice of a half/diff table (multi-part EXR); ``.bsdf``: an RGL tensor file, from
    any isotropic BRDF (a table, an analytic model; an RGL file is copied unchanged), see
    :mod:`gonio.io.rgl_write`.
    """
    name = os.fspath(path).lower()
    if name.endswith(".bsdf"):
        if lossy is not None:
            raise ParameterError("lossy encoding is only available for .brdf.h5 output")
        from gonio.io.rgl_write import write_rgl

        write_rgl(obj, path)
        return
    from gonio.io.rgl_measured import RGLMeasured

    if isinstance(obj, RGLMeasured):
        obj = obj.to_table()  # an exact evaluator: store its MERL-grid tabulation
    if lossy is not None and not name.endswith((".h5", ".hdf5")):
        raise ParameterError("lossy encoding is only available for .brdf.h5 output")
    if name.endswith((".h5", ".hdf5")):
        from gonio.io.native import write_native

        write_native(obj, path, lossy=lossy)
    elif name.endswith(".binary"):
        from gonio.io.merl import write_merl

        write_merl(obj, path)
    elif name.endswith(".exr"):
        from gonio.io.exr import write_table_slices

        write_table_slices(obj, path)
    else:
        raise ParameterError(
            f"{os.fspath(path)}: unknown output extension (use .brdf.h5, .binary, .exr or .bsdf)"
        )
