"""What the prior commands read: a library of materials, and the samples of one acquisition.

Everything goes through :func:`gonio.io.load`. A library source is a BRDF file (MERL
``.binary``, native ``*.brdf.h5`` table, RGL ``.bsdf``), a neural-BRDF archive ``ARCHIVE.zip``
(all its materials) or one member ``ARCHIVE.zip::NAME``. The samples of a reconstruction are a
run folder's ``RUN/table.brdf.h5`` (what ``gonio acquire`` writes), or any file gonio reads: a
scattered file's samples, a table's valid nodes (a sparse native table, a MERL file).
"""

from __future__ import annotations

import zipfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gonio.errors import FormatError, ParameterError

#: The file a run folder holds its samples in.
RUN_TABLE = "table.brdf.h5"


def expand_sources(sources: list[str]) -> list[tuple[str, str]]:
    """``(name, address)`` of every material the sources name, in order, names unique.

    Raises
    ------
    ParameterError
        A source that does not exist, or two materials of the same name.
    """
    out: list[tuple[str, str]] = []
    for s in sources:
        head = s.rpartition("::")[0] if "::" in s else s
        p = Path(head)
        if not p.is_file():
            raise ParameterError(f"{head}: no such file")
        if "::" not in s and zipfile.is_zipfile(p):
            from gonio.io.nbrdf import list_materials

            out.extend((n, f"{s}::{n}") for n in list_materials(p))
        elif "::" in s:
            out.append((s.rpartition("::")[2], s))
        else:
            out.append((p.name.split(".")[0], s))
    names = [n for n, _ in out]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ParameterError(f"materials named twice: {', '.join(dup[:5])}")
    return out


def load_materials(addresses: list[str]) -> Iterator[Any]:
    """Each address read with :func:`gonio.io.load`, one at a time."""
    from gonio import io

    for a in addresses:
        obj = io.load(a)
        if not hasattr(obj, "f") or type(obj).__name__ == "MeasuredSamples":
            raise ParameterError(
                f"{a}: scattered samples cannot be a prior's material; a "
                "prior needs full tables (grid them first: gonio grid)"
            )
        yield obj


@dataclass(frozen=True)
class Samples:
    """Sparse measurements: ``wi``, ``wo`` ``(n, 3)``, ``values`` and ``sigma`` (or None)
    ``(n, C)`` in sr⁻¹, ``meta`` the source's provenance."""

    wi: np.ndarray
    wo: np.ndarray
    values: np.ndarray
    sigma: np.ndarray | None
    meta: dict


def read_samples(path: str) -> Samples:
    """The samples of a run folder or of any file :func:`gonio.io.load` reads (module
    docstring)."""
    from gonio import io

    p = Path(path)
    if p.is_dir():
        if not (p / RUN_TABLE).is_file():
            raise ParameterError(f"{p}: a folder but not a run folder (no {RUN_TABLE})")
        p = p / RUN_TABLE
    elif "::" not in path and not p.exists():
        raise ParameterError(f"{path}: no such file or folder")
    obj = io.load(p if "::" not in path else path)
    if hasattr(obj, "to_samples") and not hasattr(obj, "valid_nodes"):
        obj = obj.to_samples()  # an RGL file: its own nodes
    if hasattr(obj, "valid_nodes"):
        wi, wo, values, sigma, _ = obj.valid_nodes()
    else:
        wi, wo = np.asarray(obj.wi), np.asarray(obj.wo)
        values = np.asarray(obj.values)
        sigma = None if obj.sigma is None else np.asarray(obj.sigma)
    if values.shape[0] == 0:
        raise FormatError(f"{path}: no valid samples")
    return Samples(
        np.asarray(wi, np.float64),
        np.asarray(wo, np.float64),
        np.asarray(values, np.float64),
        None if sigma is None else np.asarray(sigma, np.float64),
        dict(getattr(obj, "meta", {}) or {}),
    )
