"""Shared parsing of whitespace-separated numeric text (Cornell, ALTA)."""

from __future__ import annotations

import numpy as np

from gonio.io._common import PathLike, fail


def parse_row(path: PathLike, lineno: int, line: str) -> list[float]:
    """Parse one line of numbers; a bad token is a :class:`FormatError` naming the line."""
    out = []
    for tok in line.split():
        try:
            out.append(float(tok))
        except ValueError:
            raise fail(path, f"line {lineno}: not a number: {tok[:40]!r}") from None
    return out


def rows_to_array(path: PathLike, rows: list[list[float]], width: int, what: str) -> np.ndarray:
    """Stack rows of equal ``width`` into ``(N, width)`` and reject NaN/Inf."""
    if not rows:
        raise fail(path, f"no {what} records")
    arr = np.asarray(rows, dtype=np.float64).reshape(-1, width)
    if not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.all(np.isfinite(arr), axis=1)))
        raise fail(path, f"{bad} {what} record(s) contain NaN or Inf")
    return arr


def spherical(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Unit vectors ``(..., 3)`` from polar angle ``theta`` and azimuth ``phi`` (radians)."""
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)


def half_diff_to_directions(
    theta_h: np.ndarray, phi_h: np.ndarray, theta_d: np.ndarray, phi_d: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """NumPy twin of :func:`gonio.brdf.frames.half_diff_to_directions` (same convention).

    Parsers call it on arrays whose length differs from file to file; the JAX version would
    compile once per new shape, which dominates the time to read a small text file.
    """
    th, ph, td, pd = np.broadcast_arrays(
        *(np.asarray(a, dtype=np.float64) for a in (theta_h, phi_h, theta_d, phi_d))
    )
    d = spherical(td, pd)
    d_o = d * np.array([-1.0, -1.0, 1.0])

    def rot(v: np.ndarray) -> np.ndarray:
        cy, sy = np.cos(th), np.sin(th)
        x, y, z = v[..., 0], v[..., 1], v[..., 2]
        x, z = cy * x + sy * z, -sy * x + cy * z
        cz, sz = np.cos(ph), np.sin(ph)
        return np.stack([cz * x - sz * y, sz * x + cz * y, z], -1)

    return rot(d), rot(d_o)
