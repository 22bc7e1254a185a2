"""One-screen summaries of BRDF files (the data behind ``gonio info``)."""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from gonio.io._common import PathLike
from gonio.io.detect import detect_format


def _value_stats(values: np.ndarray, valid: np.ndarray | None) -> dict[str, Any]:
    v = np.asarray(values, dtype=np.float64)
    v = v.reshape(-1, v.shape[-1])
    if valid is not None:
        v = v[np.asarray(valid, dtype=bool).reshape(-1)]
    if v.size == 0:
        return {"min": None, "max": None, "mean": None, "per_channel_max": []}
    return {
        "min": float(v.min()),
        "max": float(v.max()),
        "mean": float(v.mean()),
        "per_channel_max": [float(x) for x in v.max(axis=0)],
    }


def _channels(ch: Any) -> dict[str, Any]:
    wl = getattr(ch, "wavelengths_nm", None)
    return {
        "kind": ch.kind,
        "names": list(ch.names),
        "primaries": ch.primaries,
        "white_point": ch.white_point,
        "wavelengths_nm": None if wl is None else [float(x) for x in np.asarray(wl)],
    }


#: How ``value_range`` of an RGL file is obtained: its stored tensor holds warped, VNDF-scaled
#: luminance samples, not BRDF values, so the file's own evaluator is sampled instead.
RGL_VALUES_NOTE = (
    "BRDF f(wi, wo) from the file's evaluator at 4096 direction pairs with both polar angles "
    "at most 80 deg (fixed seed); stored_range holds the raw tensor values, which are not 1/sr"
)


def _rgl_brdf_stats(b: Any) -> dict[str, Any]:
    """Value statistics of an RGL file's BRDF (see :data:`RGL_VALUES_NOTE`)."""
    rng = np.random.default_rng(0)
    u = rng.random((2, 4096, 2))
    cmax = np.cos(np.radians(80.0))
    ct = 1.0 - u[..., 0] * (1.0 - cmax)  # cos theta uniform in [cos 80 deg, 1]
    st = np.sqrt(1.0 - ct**2)
    p = 2 * np.pi * u[..., 1]
    w = np.stack([st * np.cos(p), st * np.sin(p), ct], -1)
    return _value_stats(np.asarray(b.f(w[0], w[1])), None)


def _native_summary(path: PathLike, out: dict[str, Any]) -> bool:
    """Fill ``out`` for a native file from its header and arrays (h5py and NumPy only: no
    TabulatedBRDF is built, so ``gonio info`` does not import JAX). False when this build's
    native reader does not offer the pieces (then the caller loads the file)."""
    from gonio.io import native

    read_arrays = getattr(native, "_read_arrays", None)
    header_of = getattr(native, "_header", None)
    if read_arrays is None or header_of is None:
        return False
    h5 = native._open(path)
    try:
        with native._Guard(path):
            header = header_of(h5, path)
            arrays = read_arrays(h5, header, path)
    finally:
        h5.close()
    values = np.asarray(arrays["values"])
    if header["kind"] == "gridded":
        g = header["grid"]
        mask = np.asarray(arrays["mask"], dtype=bool)
        out.update(
            kind="gridded",
            grid={
                "parameterization": g["parameterization"],
                "interpolation": g.get("interpolation", "linear"),
                "axes": [dict(a) for a in g["axes"]],
                "shape": list(values.shape[:-1]),
            },
            valid_fraction=float(mask.mean()),
            value_range=_value_stats(values, mask),
            has_sigma="sigma" in arrays,
            has_counts="counts" in arrays,
            raw_bytes=int(values.size * 4 + values[..., 0].size),
        )
    else:
        out.update(
            kind="scattered",
            samples=int(values.shape[0]),
            valid_fraction=1.0,
            value_range=_value_stats(values, None),
            has_sigma="sigma" in arrays,
            raw_bytes=int(values.size * 4 + values.shape[0] * 6 * 8),
        )
    ch = header["channels"]
    out["channels"] = {
        "kind": ch["kind"],
        "names": list(ch["names"]),
        "primaries": ch.get("primaries"),
        "white_point": ch.get("white_point"),
        "wavelengths_nm": ch.get("wavelengths_nm"),
    }
    out["provenance"] = dict(header.get("metadata") or {})
    out["encoding"] = header["encoding"]
    out["software"] = header["software"]
    out["created_utc"] = header["created_utc"]
    return True


def summarize(path: PathLike) -> dict[str, Any]:
    """Describe a BRDF file: format, kind, grid, channels, valid fraction, value range,
    provenance, size on disk and compression ratio (float32 in memory / bytes on disk)."""
    fmt = detect_format(path)
    size = os.path.getsize(os.fspath(path).rpartition("::")[0] or path)  # ARCHIVE.zip::NAME
    out: dict[str, Any] = {"file": os.fspath(path), "format": fmt, "size_bytes": size}
    if fmt == "rgl":
        from gonio.io.rgl import read_rgl
        from gonio.io.rgl_measured import from_rgl_file

        b = read_rgl(path)
        colour = b.fields["spectra" if b.spectral else "rgb"]
        out.update(
            kind="rgl-tensor",
            description=b.description,
            isotropic=b.isotropic,
            grid={name: list(b.fields[name].shape) for name in ("theta_i", "phi_i", "vndf")},
            channels=_channels(b.channels),
            value_range=_rgl_brdf_stats(from_rgl_file(b)),
            value_range_note=RGL_VALUES_NOTE,
            stored_range=_value_stats(np.moveaxis(colour, 2, -1), None),
            valid_fraction=1.0,
            provenance={"source": {"format": "rgl-tensor", "file": os.fspath(path)}},
            raw_bytes=int(sum(a.nbytes for a in b.fields.values())),
        )
    elif fmt == "native" and _native_summary(path, out):
        pass
    else:
        from gonio.brdf.tabulated import TabulatedBRDF
        from gonio.io import load

        obj = load(path)
        meta = dict(getattr(obj, "meta", {}) or {})
        if isinstance(obj, TabulatedBRDF):
            mask = None if obj.mask is None else np.asarray(obj.mask, dtype=bool)
            values = np.asarray(obj.values)
            out.update(
                kind="gridded",
                grid={
                    "parameterization": obj.parameterization,
                    "interpolation": obj.interpolation,
                    "axes": [
                        {
                            "name": a.name,
                            "size": int(a.size),
                            "lo": float(a.lo),
                            "hi": float(a.hi),
                            "warp": a.warp,
                            "periodic": bool(a.periodic),
                            "node_offset": float(a.node_offset),
                        }
                        for a in obj.axes
                    ],
                    "shape": list(values.shape[:-1]),
                },
                valid_fraction=1.0 if mask is None else float(mask.mean()),
                value_range=_value_stats(values, mask),
                has_sigma=obj.sigma is not None,
                has_counts=obj.counts is not None,
                raw_bytes=int(values.size * 4 + values[..., 0].size),
            )
        else:
            values = np.asarray(obj.values)
            out.update(
                kind="scattered",
                samples=int(values.shape[0]),
                valid_fraction=1.0,
                value_range=_value_stats(values, None),
                has_sigma=obj.sigma is not None,
                raw_bytes=int(values.size * 4 + values.shape[0] * 6 * 8),
            )
        out["channels"] = _channels(obj.channels)
        out["provenance"] = meta
        if fmt == "native":
            from gonio.io.native import read_header

            h = read_header(path)
            out["encoding"] = h["encoding"]
            out["software"] = h["software"]
            out["created_utc"] = h["created_utc"]
    out["compression_ratio"] = float(out["raw_bytes"]) / max(size, 1)
    return out
