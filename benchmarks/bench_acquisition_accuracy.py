"""Accuracy of a simulated acquisition: measured BRDF values against the simulated ground truth.

Runs ``gonio acquire --rig sim --plan iso-reciprocal`` (the imaging camera: DNG brackets, HDR
merge, ChArUco pose, white-reference radiometry) into a temporary folder and reports, over every
sample and colour channel, ``|measured - truth| / sigma`` with the truth evaluated at the
directions the run reports, and the camera-direction error of each frame (ChArUco pose against
the read-back joint angles). Targets (issue "Imaging"): median <= 1, p95 <= 2.5, geometry
< 0.05 deg; a calibrated Gaussian sigma gives median 0.674, p95 1.96 and RMS 1.

One run has only 16 samples (48 values): its median |z| scatters by about +-0.11 from run to run
(seed 7 alone gives 0.80), so the run is repeated with several ``[sim] seed`` values (sensor and
servo noise), ``--seeds`` (default 7 8 9 10 11, about a minute). Writes
``benchmarks/results/acquisition_accuracy.csv``.
"""

from __future__ import annotations

import argparse
import csv
import re
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from gonio.acquire.engine import acquire
from gonio.acquire.journal import Journal
from gonio.brdf import models
from gonio.rigs.config import load_rig, parse_rig
from gonio.rigs.kinematics import Kinematics

RESULTS = Path(__file__).resolve().parent / "results"


def _rig_with_seed(seed: int):
    """The shipped ``sim`` rig with its ``[sim] seed`` (the first ``seed =`` line) replaced."""
    base = load_rig("sim")
    text = re.sub(r"(?m)^seed = \d+", f"seed = {seed}", base.text, count=1)
    return parse_rig(text, base.source)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[7, 8, 9, 10, 11],
                    help="[sim] seeds, one acquisition each")  # fmt: skip
    args = ap.parse_args(argv)
    z, geo, n_samples = [], [], 0
    complete = True
    t0 = time.perf_counter()
    for seed in args.seeds:
        with tempfile.TemporaryDirectory() as tmp:
            run = Path(tmp) / "run"
            summary = acquire(run, _rig_with_seed(seed), "iso-reciprocal", progress=True)
            complete &= summary.complete
            j = Journal(run)
            try:
                rig = parse_rig(j.get_meta("rig_text"))
                rows = j.samples()
            finally:
                j.close()
        kin = Kinematics(rig)
        truth = models.Node.from_dict(rig.sim.sample)
        n_samples += len(rows)
        for r in rows:
            z.append((r.value - np.asarray(truth.f(r.wi, r.wo))) / r.sigma)
            _, wo_true = kin.forward(kin.joints_deg_to_pose(r.joints_deg))
            geo.append(float(np.degrees(np.arccos(np.clip(wo_true @ r.wo, -1, 1)))))
    elapsed = time.perf_counter() - t0
    rms = float(np.sqrt(np.mean(np.concatenate(z) ** 2)))
    z = np.abs(np.concatenate(z))
    out = {
        "seeds": " ".join(str(s) for s in args.seeds),
        "samples": n_samples,
        "values": int(z.size),
        "median_abs_z": float(np.median(z)),
        "p95_abs_z": float(np.percentile(z, 95)),
        "max_abs_z": float(z.max()),
        "rms_z": rms,
        "geometry_max_deg": max(geo),
        "wall_s": round(elapsed, 1),
        "complete": complete,
    }
    RESULTS.mkdir(exist_ok=True)
    with open(RESULTS / "acquisition_accuracy.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(out))
        w.writeheader()
        w.writerow(out)
    print("| seeds | samples | values | median abs z | p95 abs z | max abs z | RMS z |"
          " geometry max (deg) |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    cells = [out["seeds"], out["samples"], out["values"], f"{out['median_abs_z']:.2f}",
             f"{out['p95_abs_z']:.2f}", f"{out['max_abs_z']:.2f}", f"{rms:.2f}",
             f"{out['geometry_max_deg']:.3f}"]  # fmt: skip
    print("| " + " | ".join(str(c) for c in cells) + " |")
    return 0


def write_tables() -> None:
    """Rewrite this benchmark's table in benchmarks/README.md from its CSV."""
    import _tables

    columns = [
        ("seeds", "seeds"),
        ("configurations", "samples"),
        ("values", "values"),
        ("median \\|z\\|", "median_abs_z"),
        ("95th pct \\|z\\|", "p95_abs_z"),
        ("max \\|z\\|", "max_abs_z"),
        ("RMS z", "rms_z"),
        ("camera direction, max error (deg)", "geometry_max_deg"),
        ("wall (s)", "wall_s"),
    ]
    rows = _tables.read("acquisition_accuracy.csv")
    _tables.write("acquisition_accuracy", _tables.markdown(rows, columns))


if __name__ == "__main__":
    _rc = main()
    if not _rc:
        write_tables()
    sys.exit(_rc)
