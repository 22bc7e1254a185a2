"""The one tuning / held-out split of the NBRDF materials (issue #40).

The default fit's families, loss and thresholds are chosen on the tuning half only; benchmarks
report the held-out half (and all materials) separately, so that the numbers are not tuned to
the materials they are scored on. The split is deterministic: the names of the complete
materials of ``merl_nbrdf.zip`` (both the ``.json`` and the ``.h5`` member present) sorted,
permuted by ``numpy.random.default_rng(0).permutation``, the first half tuning.

``python benchmarks/_nbrdf_split.py`` prints both halves.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

#: The shared NBRDF archive (see ``../shared/data/nbrdf/README.md``).
ARCHIVE = (
    Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "nbrdf" / "merl_nbrdf.zip"
)

#: Seed of the permutation and the number of tuning materials (the first ``N_TUNING``).
SEED, N_TUNING = 0, 44


def complete_materials(archive: Path = ARCHIVE) -> list[str]:
    """Sorted names of the materials with both a ``.json`` and an ``.h5`` member."""
    with zipfile.ZipFile(archive) as z:
        names = [Path(n) for n in z.namelist()]
    stems = {ext: {p.stem for p in names if p.suffix == ext} for ext in (".json", ".h5")}
    return sorted(stems[".json"] & stems[".h5"])


def split(archive: Path = ARCHIVE) -> tuple[list[str], list[str]]:
    """``(tuning, held_out)``: material names, each list in permutation order."""
    names = complete_materials(archive)
    order = np.random.default_rng(SEED).permutation(len(names))
    chosen = [names[i] for i in order]
    return chosen[:N_TUNING], chosen[N_TUNING:]


if __name__ == "__main__":
    tuning, held_out = split()
    print(f"tuning ({len(tuning)}):", " ".join(tuning))
    print(f"held out ({len(held_out)}):", " ".join(held_out))
