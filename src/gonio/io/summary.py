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


def summarize(path: PathLike) -> dict[str, Any]:
    """Describe a BRDF file: format, kind, grid, channels, valid fraction, value range,
    provenance, size on disk and compression ratio (float32 in memory / bytes on disk)."""
    fmt = detect_format(path)
    size = os.path.getsize(os.fspath(path).rpartition("::")[0] or path)  # ARCHIVE.zip::NAME
    out: dict[str, Any] = {"file": os.fspath(path), "format": fmt, "size_bytes": size}
    if fmt == "rgl":
        from gonio.io.rgl import read_rgl

        b = read_rgl(path)
        colour = b.fields["spectra" if b.spectral else "rgb"]
        out.update(
            kind="rgl-tensor",
            description=b.description,
            isotropic=b.isotropic,
            grid={name: list(b.fields[name].shape) for name in ("theta_i", "phi_i", "vndf")},
            channels=_channels(b.channels),
            value_range=_value_stats(np.moveaxis(colour, 2, -1), None),
            valid_fraction=1.0,
            provenance={"source": {"format": "rgl-tensor", "file": os.fspath(path)}},
            raw_bytes=int(sum(a.nbytes for a in b.fields.values())),
        )
    else:
        from gonio.io import load

        obj = load(path)
        meta = dict(getattr(obj, "meta", {}) or {})
        if hasattr(obj, "axes"):
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
