"""A run's measurements as tables: scattered samples, a gridded half/diff table, reciprocity.

``RUN/table.brdf.h5`` holds the scattered samples (:class:`MeasuredSamples`, with sigma) at the
root and, in the group ``/gridded``, an isotropic half/diff table resampled from them
(:func:`grid_samples`) with a coverage mask, sigma and counts; see ``data-schema/FORMAT.md``.

Resampling is binning, not interpolation (:func:`gonio.brdf.gridding.grid_samples`, re-exported
here): nodes without samples are masked invalid, the table never claims data it does not have.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gonio.brdf.gridding import default_grid, grid_samples, half_diff_iso
from gonio.brdf.measured import MeasuredSamples
from gonio.brdf.tabulated import Channels

__all__ = [
    "default_grid",
    "grid_samples",
    "half_diff_iso",
    "reciprocal_pairs",
    "reciprocity_summary",
    "write_run_tables",
]


@dataclass(frozen=True)
class ReciprocityPair:
    """Two measurements of a plan whose targets swap light and camera.

    ``rel_diff`` (C,) is ``|f_a - f_b| / ((f_a + f_b) / 2)``; ``z`` (C,) is
    ``(f_a - f_b) / sqrt(sigma_a^2 + sigma_b^2)`` (None without sigma). ``mismatch_deg`` is how
    far the directions actually measured are from an exact swap (the larger of the angles
    between wi_a and wo_b and between wo_a and wi_b; isotropic pairs compare the polar angles and
    the azimuth difference), None when they were not given: on a steep lobe a tenth of a degree
    of settling error moves f by percents, which the difference then contains.
    """

    a: int
    b: int
    rel_diff: np.ndarray
    z: np.ndarray | None
    mismatch_deg: float | None = None


def reciprocal_pairs(
    targets: dict[int, tuple[np.ndarray, np.ndarray]],
    measured: dict[int, tuple[np.ndarray, np.ndarray | None]],
    isotropic: bool = True,
    tol_deg: float = 0.5,
    directions: dict[int, tuple[np.ndarray, np.ndarray]] | None = None,
) -> list[ReciprocityPair]:
    """Pairs (a, b) of configurations with ``wi_a = wo_b`` and ``wo_a = wi_b`` (targets).

    ``targets`` maps a configuration index to its planned (wi, wo); ``measured`` to its
    (value (C,), sigma (C,) or None). With ``isotropic`` only (theta_i, theta_o, |delta phi|)
    must swap (the sample's azimuth is free). ``directions`` maps an index to the (wi, wo)
    actually measured, for :attr:`ReciprocityPair.mismatch_deg`.
    """
    keys = sorted(k for k in targets if k in measured)

    def signature(wi, wo):
        ti, to = math.acos(np.clip(wi[2], -1, 1)), math.acos(np.clip(wo[2], -1, 1))
        if isotropic:
            dphi = abs(
                math.remainder(math.atan2(wi[1], wi[0]) - math.atan2(wo[1], wo[0]), 2 * math.pi)
            )
            return np.degrees([ti, to, dphi if ti > 1e-6 and to > 1e-6 else 0.0])
        return np.concatenate([np.asarray(wi), np.asarray(wo)])

    sig = {k: signature(*targets[k]) for k in keys}
    swapped = {k: signature(targets[k][1], targets[k][0]) for k in keys}
    tol = tol_deg if isotropic else math.radians(tol_deg)
    out = []
    used: set[int] = set()
    for a in keys:
        if a in used:
            continue
        if np.allclose(sig[a], swapped[a], atol=tol):
            continue  # its own reciprocal (theta_i = theta_o): nothing to compare
        for b in keys:
            if b <= a or b in used:
                continue
            if np.allclose(sig[b], swapped[a], atol=tol):
                fa, sa = measured[a]
                fb, sb = measured[b]
                fa, fb = np.asarray(fa, float), np.asarray(fb, float)
                rel = np.abs(fa - fb) / np.maximum(np.abs(fa + fb) / 2, 1e-30)
                z = None
                if sa is not None and sb is not None:
                    z = (fa - fb) / np.sqrt(np.asarray(sa) ** 2 + np.asarray(sb) ** 2)
                mis = None
                if directions is not None and a in directions and b in directions:
                    sa_ = signature(*directions[a])
                    sb_ = signature(directions[b][1], directions[b][0])
                    if isotropic:
                        mis = float(np.max(np.abs(sa_ - sb_)))
                    else:
                        mis = float(
                            np.degrees(
                                max(
                                    np.arccos(np.clip(sa_[:3] @ sb_[:3], -1, 1)),
                                    np.arccos(np.clip(sa_[3:] @ sb_[3:], -1, 1)),
                                )
                            )
                        )
                out.append(ReciprocityPair(a, b, rel, z, mis))
                used.update((a, b))
                break
    return out


def reciprocity_summary(pairs: list[ReciprocityPair]) -> dict:
    """Median and maximum relative difference (and |z|) over the pairs, JSON-ready."""
    if not pairs:
        return {"pairs": 0}
    rel = np.concatenate([p.rel_diff for p in pairs])
    out = {
        "pairs": len(pairs),
        "rel_diff_median": float(np.median(rel)),
        "rel_diff_max": float(np.max(rel)),
    }
    mis = [p.mismatch_deg for p in pairs if p.mismatch_deg is not None]
    if mis:
        out["direction_mismatch_deg_max"] = float(np.max(mis))
    zs = [p.z for p in pairs if p.z is not None]
    if zs:
        z = np.abs(np.concatenate(zs))
        out["abs_z_median"] = float(np.median(z))
        out["abs_z_p95"] = float(np.percentile(z, 95))
    return out


def write_run_tables(journal, rig, channels) -> tuple[str | None, str, dict]:
    """Write ``RUN/table.brdf.h5`` (samples at the root, gridded table in ``/gridded``).

    Returns (path or None, note, reciprocity summary).
    """
    from gonio.io.native import write_native

    rows = journal.samples()
    if not rows:
        return None, "table not written: no samples", {}
    ch = Channels.rgb() if tuple(channels) == ("R", "G", "B") else Channels.mono()
    configs = {c.idx: c for c in journal.configs()}
    targets = {r.idx: (np.asarray(configs[r.idx].wi), np.asarray(configs[r.idx].wo)) for r in rows}
    iso = all(configs[r.idx].isotropic for r in rows)
    pairs = reciprocal_pairs(
        targets,
        {r.idx: (r.value, r.sigma) for r in rows},
        isotropic=iso,
        directions={r.idx: (np.asarray(r.wi), np.asarray(r.wo)) for r in rows},
    )
    recip = reciprocity_summary(pairs)
    meta = {
        "source": "gonio acquire",
        "rig": {"name": rig.name, "source": rig.source},
        "run": str(journal.run_dir),
        "reciprocity": recip,
    }
    samples = MeasuredSamples(
        wi=np.array([r.wi for r in rows]),
        wo=np.array([r.wo for r in rows]),
        values=np.array([r.value for r in rows]),
        sigma=np.array([r.sigma for r in rows]),
        channels=ch,
        weights=None,
        meta=meta,
    )
    grid = grid_samples(samples)
    path = journal.run_dir / "table.brdf.h5"
    write_native(samples, path, groups={"gridded": grid})
    note = (
        f"{len(rows)} samples; gridded {int(grid.mask.sum())}/{grid.mask.size} cells covered;"
        f" reciprocity: {recip.get('pairs', 0)} pairs"
    )
    if not recip.get("pairs"):
        note += (
            " (no configuration was measured with light and camera swapped;"
            " plan iso-reciprocal does)"
        )
    if recip.get("pairs"):
        note += (
            f", relative difference median {recip['rel_diff_median']:.3g}"
            f" max {recip['rel_diff_max']:.3g}"
        )
        if "direction_mismatch_deg_max" in recip:
            note += f" (measured directions up to {recip['direction_mismatch_deg_max']:.2f} deg"
            note += " from an exact swap)"
    return str(path), note, recip
