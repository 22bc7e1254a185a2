"""Helpers for corruption tests: truncations and byte flips of real files, in a temp folder."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from gonio.errors import FormatError


def truncation_offsets(size: int, n: int = 24, seed: int = 0) -> list[int]:
    """Offsets spread over the file: the first bytes, every header byte region, random ones."""
    rng = np.random.default_rng(seed)
    fixed = [0, 1, 4, 8, 11, 12, 13, 14, 17, 18, 20, 40, 100, 300, size // 2, size - 1]
    rand = rng.integers(1, size, size=n).tolist()
    return sorted({o for o in fixed + rand if 0 <= o < size})


def variants(src: Path, tmp: Path, n_flips: int = 24, seed: int = 0) -> Iterator[tuple[str, Path]]:
    """Yield ``(description, path)`` of truncated and byte-flipped copies of ``src``."""
    data = src.read_bytes()
    rng = np.random.default_rng(seed)
    for off in truncation_offsets(len(data), seed=seed):
        p = tmp / f"trunc_{off}_{src.name}"
        p.write_bytes(data[:off])
        yield f"truncated at {off}", p
    # flips: header region and random positions
    positions = sorted(
        set(list(range(0, min(64, len(data)), 5)) + rng.integers(0, len(data), n_flips).tolist())
    )
    for pos in positions:
        b = bytearray(data)
        b[pos] ^= 0xFF
        p = tmp / f"flip_{pos}_{src.name}"
        p.write_bytes(bytes(b))
        yield f"byte {pos} flipped", p


def assert_clean(
    load: Callable[[Path], object], path: Path, what: str, check: Callable[[object], None]
) -> str:
    """Load must either raise a one-line FormatError naming the file, or give a sane result."""
    try:
        obj = load(path)
    except FormatError as exc:
        msg = str(exc)
        assert "\n" not in msg, f"{what}: multi-line message {msg!r}"
        assert str(path) in msg, f"{what}: message does not name the file: {msg!r}"
        return "error"
    check(obj)
    return "parsed"
