"""OpenEXR helpers: linear float images, and half/diff table slices viewable in any EXR viewer.

A table slice file is a multi-part EXR with one part per ``phi_d`` node, named
``phi_d=<degrees>``; each part is a ``theta_h`` (rows, top = 0) x ``theta_d`` (columns, left = 0)
image with one FLOAT channel per table channel (R, G, B for RGB tables) plus ``A`` = 1 at valid
cells, 0 at invalid ones (whose colour is 0). Part attributes ``gonio_phi_d_rad``,
``gonio_units`` = "1/sr", ``gonio_axes`` and ``gonio_channels`` (JSON, channel order) record the
mapping.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from gonio._bounded import MAX_COMPRESSION_RATIO, MAX_DECODED_BYTES, loads_json
from gonio.errors import GonioError, ParameterError
from gonio.io._common import PathLike, atomic_output, check_input_file, fail
from gonio.io._sanity import check_brdf_values
from gonio.io.strict_json import dumps_json


def _openexr() -> Any:
    import OpenEXR

    return OpenEXR


def _channel_names(n: int, names: tuple[str, ...] | list[str] | None) -> list[str]:
    if names is not None:
        if len(names) != n:
            raise ParameterError(f"{len(names)} channel names for {n} channels")
        return [str(x) for x in names]
    return {1: ["Y"], 3: ["R", "G", "B"], 4: ["R", "G", "B", "A"]}.get(
        n, [f"c{i}" for i in range(n)]
    )


def _standard_order(names: list[str]) -> list[str]:
    """R, G, B, A first (EXR stores channels alphabetically), then the rest in stored order."""
    first = [n for n in ("R", "G", "B", "A", "Y") if n in names]
    return first + [n for n in names if n not in first]


def _header(extra: dict | None = None) -> dict:
    ox = _openexr()
    h: dict[str, Any] = {"compression": ox.ZIP_COMPRESSION, "type": ox.scanlineimage}
    for k, v in (extra or {}).items():
        h[k] = v
    return h


def write_exr(
    path: PathLike,
    image: np.ndarray,
    channel_names: tuple[str, ...] | list[str] | None = None,
    attributes: dict[str, str] | None = None,
) -> None:
    """Write a linear float image ``(H, W)`` or ``(H, W, C)`` as a single-part EXR, atomically.

    Channels are stored as 32-bit FLOAT, ZIP-compressed. Default names: Y (1), R G B (3),
    R G B A (4), else c0, c1, ...
    """
    ox = _openexr()
    img = np.asarray(image, dtype=np.float32)
    if img.ndim == 2:
        img = img[..., None]
    if img.ndim != 3 or img.shape[0] < 1 or img.shape[1] < 1:
        raise ParameterError(f"image must be (H, W) or (H, W, C), got {img.shape}")
    names = _channel_names(img.shape[2], channel_names)
    channels = {n: np.ascontiguousarray(img[..., i]) for i, n in enumerate(names)}
    with atomic_output(path, suffix=".exr") as tmp:
        with ox.File(_header(attributes), channels) as f:
            f.write(str(tmp))


def _check_budget(ox: Any, p: Any) -> None:
    """Refuse, from the headers alone, a file whose pixels would exceed the memory budget.

    Every part's data window must be non-empty, and all parts together may decode to at most
    :data:`gonio._bounded.MAX_DECODED_BYTES` (counting 4 bytes per channel sample) and to at
    most :data:`gonio._bounded.MAX_COMPRESSION_RATIO` times the file's size.
    """
    try:
        with ox.File(str(p), header_only=True) as f:
            total = 0
            for part in f.parts:
                lo, hi = (np.asarray(c, dtype=np.int64) for c in part.header["dataWindow"])
                w, h = (hi - lo + 1).tolist()
                if w < 1 or h < 1:
                    raise fail(p, f"EXR part {part.name()!r}: empty data window {w}x{h}")
                total += w * h * max(1, len(part.header.get("channels", ()) or ())) * 4
    except (RuntimeError, OSError, ValueError, KeyError, TypeError) as exc:
        raise fail(p, f"cannot read EXR header ({exc})") from None
    size = p.stat().st_size
    if total > MAX_DECODED_BYTES or total > MAX_COMPRESSION_RATIO * size + (1 << 20):
        raise fail(p, f"EXR header declares {total} bytes of pixels in a {size}-byte file")


def read_exr(path: PathLike, part: int = 0) -> tuple[np.ndarray, list[str]]:
    """Read one part of an EXR file: float32 ``(H, W, C)`` and the channel names (sorted)."""
    ox = _openexr()
    p = check_input_file(path)
    _check_budget(ox, p)
    try:
        with ox.File(str(p), separate_channels=True) as f:
            parts = f.parts
            if not (0 <= part < len(parts)):
                raise fail(p, f"EXR has {len(parts)} part(s), no part {part}")
            chans = parts[part].channels
            names = _standard_order(list(chans))
            img = np.stack([np.asarray(chans[n].pixels, dtype=np.float32) for n in names], -1)
    except (RuntimeError, OSError, ValueError) as exc:
        raise fail(p, f"cannot read EXR ({exc})") from None
    return img, names


def write_table_slices(table: Any, path: PathLike, every: int = 1) -> int:
    """Write an isotropic half/diff table as a multi-part EXR, one part per ``phi_d`` node.

    Parameters
    ----------
    table : TabulatedBRDF
        ``half_diff_iso`` table with axes (theta_h, theta_d, phi_d).
    every : int
        Keep every ``every``-th ``phi_d`` slice (1 = all).

    Returns
    -------
    int
        Number of parts written.
    """
    from gonio.brdf.tabulated import TabulatedBRDF

    ox = _openexr()
    if not isinstance(table, TabulatedBRDF) or table.parameterization != "half_diff_iso":
        raise ParameterError(
            "EXR slices need an isotropic half/diff table (theta_h, theta_d, phi_d)"
        )
    if every < 1:
        raise ParameterError("every must be >= 1")
    values = np.asarray(table.values, dtype=np.float32)
    mask = (
        np.ones(values.shape[:-1], bool)
        if table.mask is None
        else np.asarray(table.mask, dtype=bool)
    )
    names = list(table.channels.names)
    if len(names) == 3:
        names = ["R", "G", "B"]
    if "A" in names:
        raise ParameterError("a table channel named 'A' clashes with the validity channel")
    axes_json = dumps_json(
        [
            {
                "name": a.name,
                "size": a.size,
                "lo": a.lo,
                "hi": a.hi,
                "warp": a.warp,
                "node_offset": a.node_offset,
            }
            for a in table.axes
        ]
    )
    phi = np.asarray(table.axes[2].nodes(), dtype=np.float64)
    kept = np.arange(0, values.shape[2], every)
    # the reader's checks, on what it will read: never write a file it refuses
    stored = np.where(mask[..., None], values, np.float32(0))
    _check_slices(path, stored[:, :, kept], mask[:, :, kept], phi[kept])
    parts = []
    for k in range(0, values.shape[2], every):
        channels = {
            n: np.ascontiguousarray(np.where(mask[:, :, k], values[:, :, k, i], 0))
            for i, n in enumerate(names)
        }
        channels["A"] = mask[:, :, k].astype(np.float32)
        header = _header(
            {
                "gonio_phi_d_rad": f"{phi[k]:.9g}",
                "gonio_units": "1/sr",
                "gonio_axes": axes_json,
                "gonio_channels": dumps_json(names),
            }
        )
        parts.append(ox.Part(header, channels, f"phi_d={math.degrees(phi[k]):.3f}"))
    with atomic_output(path, suffix=".exr") as tmp:
        with ox.File(parts) as f:
            f.write(str(tmp))
    return len(parts)


#: Part attributes that mark a table slice file (see the module docstring).
SLICE_KEYS = frozenset({"gonio_phi_d_rad", "gonio_units"})


def holds_table_slices(path: PathLike) -> bool:
    """True when ``path`` is an EXR file whose header marks it as table slices
    (:func:`write_table_slices`); False for any other file, readable or not (header only)."""
    try:
        with _openexr().File(str(path), header_only=True) as f:
            # read the keys while the file is open (the header is not kept after closing)
            return any(SLICE_KEYS & set(part.header.keys()) for part in f.parts)
    except Exception:  # OpenEXR raises plain exceptions on files it cannot read
        return False


def read_table_slices(path: PathLike) -> dict[str, Any]:
    """Read a file written by :func:`write_table_slices`.

    Returns
    -------
    dict
        ``values`` (n_theta_h, n_theta_d, n_parts, C) float32, ``mask`` (…, n_parts) bool,
        ``phi_d`` (n_parts,) radians, ``channels`` (names), ``axes`` (list of dicts).
    """
    ox = _openexr()
    p = check_input_file(path)
    _check_budget(ox, p)
    try:
        with ox.File(str(p), separate_channels=True) as f:
            vals, masks, phis = [], [], []
            names: list[str] = []
            axes = None
            for part in f.parts:
                hdr = part.header
                if "gonio_phi_d_rad" not in hdr:
                    raise fail(p, "EXR part without gonio_phi_d_rad: not a gonio table slice")
                phis.append(float(hdr["gonio_phi_d_rad"]))
                axes = loads_json(str(hdr["gonio_axes"]).encode(), f"{p} gonio_axes")
                chans = part.channels
                names = loads_json(str(hdr["gonio_channels"]).encode(), f"{p} gonio_channels")
                if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
                    raise fail(p, "gonio_channels is not a list of channel names")
                vals.append(np.stack([np.asarray(chans[n].pixels, np.float32) for n in names], -1))
                masks.append(np.asarray(chans["A"].pixels) > 0.5)
        if not vals:
            raise fail(p, "EXR file has no table slice")
        values, mask = np.stack(vals, axis=2), np.stack(masks, axis=2)
    except GonioError:
        raise
    except (RuntimeError, OSError, ValueError, KeyError, TypeError) as exc:
        raise fail(p, f"cannot read EXR table slices ({exc})") from None
    phi = np.asarray(phis)
    _check_slices(p, values, mask, phi)
    return {"values": values, "mask": mask, "phi_d": phi, "channels": names, "axes": axes}


def _check_slices(path: PathLike, values: np.ndarray, mask: np.ndarray, phi: np.ndarray) -> None:
    """The checks of table slices, on read and before writing: ``phi_d`` of each part in
    [0, 2 pi], values a BRDF at valid pixels (:func:`gonio.io._sanity.check_brdf_values`)."""
    if not np.all(np.isfinite(phi)) or np.any(phi < 0) or np.any(phi > 2 * math.pi + 1e-6):
        raise fail(path, "gonio_phi_d_rad outside [0, 2 pi]")
    check_brdf_values(path, "slice values", values, mask)
