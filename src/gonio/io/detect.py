"""Detect a BRDF file's format from its content (magic numbers, headers), then its extension."""

from __future__ import annotations

import os

import numpy as np

from gonio.io._common import PathLike, check_input_file, fail

FORMATS = ("native", "merl", "rgl", "alta", "cornell", "exr", "nbrdf")
_EXR_MAGIC = b"\x76\x2f\x31\x01"
_BY_EXTENSION = {
    ".h5": "native",
    ".hdf5": "native",
    ".binary": "merl",
    ".bsdf": "rgl",
    ".alta": "alta",
    ".dat": "alta",
    ".brdf": "cornell",
    ".exr": "exr",
}


def _looks_merl(head: bytes, size: int) -> bool:
    if size < 12:
        return False
    dims = np.frombuffer(head[:12], dtype="<i4")
    if np.any(dims <= 0) or np.any(dims > 1 << 16):
        return False
    return 12 + 24 * int(np.prod(dims.astype(np.int64))) == size


def _text_kind(head: bytes) -> str | None:
    if b"\x00" in head:
        return None
    try:
        text = head.decode("utf-8")
    except UnicodeDecodeError:
        # a multi-byte character may be cut at the end of the head
        try:
            text = head[:-4].decode("utf-8")
        except UnicodeDecodeError:
            return None
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    if any(ln.upper().startswith(("#DIM", "#PARAM_IN", "#PARAM_OUT")) for ln in lines):
        return "alta"
    data = [ln for ln in lines if not ln.startswith("#")]
    if data:
        first = data[0].split()[0]
        if first.isdigit() and len(data[0].split()) == 1:
            return "cornell"
    return None


def detect_format(path: PathLike) -> str:
    """Name of the format of ``path``: one of :data:`FORMATS`.

    Content decides first: the HDF5 signature (native), ``tensor_file`` (RGL), the EXR magic, a
    MERL header whose dimensions match the file size, ALTA ``#DIM``/``#PARAM_*`` headers, or a
    Cornell wavelength-count line. Only if the content is not recognized does the extension
    decide (so a truncated file still reaches its own parser, which reports what is wrong).

    ``"ARCHIVE.zip::NAME"`` (a material of a neural-BRDF zip) and a bare zip archive are
    ``"nbrdf"``.

    Raises
    ------
    FormatError
        A directory, a missing file, or content and extension both unrecognized.
    """
    text = os.fspath(path)
    if "::" in text:
        check_input_file(text.rpartition("::")[0])
        return "nbrdf"
    p = check_input_file(path)
    size = p.stat().st_size
    if size == 0:
        raise fail(p, "empty file")
    with open(p, "rb") as fh:
        head = fh.read(4096)
    if head.startswith(b"\x89HDF\r\n\x1a\n"):
        return "native"
    if head.startswith(b"tensor_file\x00"):
        return "rgl"
    if head.startswith(_EXR_MAGIC):
        return "exr"
    if head.startswith(b"PK\x03\x04"):
        return "nbrdf"
    if _looks_merl(head, size):
        return "merl"
    kind = _text_kind(head)
    if kind is not None:
        return kind
    name = os.path.basename(os.fspath(p)).lower()
    for ext, fmt in _BY_EXTENSION.items():
        if name.endswith(ext):
            return fmt
    raise fail(p, "unrecognized file format (not a gonio, MERL, RGL, ALTA or Cornell file)")
