"""The deterministic part of the demo's measurement error: the full ``demo`` plan, noise-free.

Acquires the full ``demo`` plan on the shipped ``sim`` rig (imaging camera, the built-in paint)
with the sensor returning its expected DN (no shot, read or dark noise; rounding and clipping
kept), so that what differs from the truth is the bias of the image formation and measurement
chain, the same in every simulator seed. With ``r = (f - truth) / sigma`` per value (sigma the
run's own) and ``J`` the Jacobian of the Lambert + Torrance-Sparrow values over sigma at the
true parameters, a seed's ``Delta chi2 = chi2(truth) - chi2(fit)`` has the mean
``7 + lambda``, ``lambda = r^T J (J^T J)^-1 J^T r`` (the non-centrality the bias adds), and the
fitted parameters move by ``(J^T J)^-1 J^T r`` (reported in units of their standard deviation).
``--workdir`` keeps the run (a second call only evaluates it). Appends a row to
``benchmarks/results/truth_noise_free.csv``.
"""

from __future__ import annotations

import argparse
import csv
import re
import sys
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
NAMES = ["albedo_r", "albedo_g", "albedo_b", "alpha", "f0_r", "f0_g", "f0_b"]
TRUTH = np.array([0.55, 0.22, 0.06, 0.18, 0.05, 0.05, 0.05])  # the built-in paint


def expected_dn(self, rate, exposure_s, seed, key=""):
    """:meth:`SensorModel.expose` without noise: the expected DN, rounded and clipped."""
    rate = np.asarray(rate, dtype=np.float64)
    if rate.ndim == 3:
        rate = self.mosaic(rate)
    e = np.minimum((rate + self.dark_current) * exposure_s, self.full_well)
    top = min(self.white_level, (1 << self.bits) - 1)
    return np.clip(np.rint(self.gain * e) + self.black_level, 0, top).astype(np.uint16), exposure_s


def acquire_noise_free(workdir: Path, seed: int) -> tuple[Path, float]:
    from gonio.acquire.engine import acquire
    from gonio.demo.materials import builtin_material
    from gonio.demo.pipeline import rig_text
    from gonio.rigs.sim.sensor import SensorModel

    table = workdir / "run" / "table.brdf.h5"
    if table.exists():
        return table, 0.0
    SensorModel.expose = expected_dn  # this process only
    workdir.mkdir(parents=True, exist_ok=True)
    text = re.sub(r"(?m)^seed = \d+", f"seed = {seed}", rig_text(builtin_material()), count=1)
    (workdir / "rig.toml").write_text(text, encoding="utf-8")
    t0 = time.monotonic()
    acquire(workdir / "run", workdir / "rig.toml", "demo", progress=False)
    return table, time.monotonic() - t0


def analyse(table: Path) -> dict:
    from gonio import io
    from gonio.brdf import models

    s = io.load(table)
    v, sg = np.asarray(s.values), np.asarray(s.sigma)

    def f(p):
        m = models.Lambert(albedo=p[0:3]) + models.TorranceSparrow(
            alpha=p[3], distribution="beckmann", shadowing="vcavity",
            fresnel=models.Schlick(f0=p[4:7]),
        )  # fmt: skip
        return np.asarray(m.f(s.wi, s.wo))

    f0 = f(TRUTH)
    r = ((v - f0) / sg).ravel()
    jac = np.stack([((f(TRUTH + 1e-6 * np.eye(7)[i]) - f0) / 1e-6 / sg).ravel()
                    for i in range(7)], 1)  # fmt: skip
    a = jac.T @ jac
    g = jac.T @ r
    delta = np.linalg.solve(a, g)
    sd = np.sqrt(np.diag(np.linalg.inv(a)))
    row = {"values": r.size, "rms_r": float(np.sqrt(np.mean(r**2))), "mean_r": float(r.mean()),
           "max_abs_r": float(np.max(np.abs(r))), "lambda": float(g @ delta)}  # fmt: skip
    row.update({f"shift_{k}": float(x) for k, x in zip(NAMES, delta / sd, strict=True)})
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", type=Path, required=True, help="keep the run here")
    ap.add_argument("--seed", type=int, default=1, help="[sim] seed (settle errors)")
    ap.add_argument("--label", default="", help="what this run measures (a row label)")
    args = ap.parse_args(argv)
    table, acq_s = acquire_noise_free(args.workdir, args.seed)
    row = {"label": args.label, "seed": args.seed, **analyse(table), "acquire_s": round(acq_s, 1)}
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / "truth_noise_free.csv"
    new = not path.exists()
    with open(path, "a", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(row))
        if new:
            w.writeheader()
        w.writerow(row)
    print(", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
