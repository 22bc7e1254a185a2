"""Where the truth check's excess Delta chi2 comes from, on runs ``bench_truth_check.py`` kept.

Linearized at the truth (the built-in paint's Lambert + Torrance-Sparrow), per run:

* ``u = L^T (p_hat - p_true)``, the whitened parameter error (``A = J^T W J = L L^T``), so that
  ``Delta chi2 = |u|^2`` and, for unbiased values with correct and independent sigma,
  ``u ~ N(0, I_7)``; the signed ``z`` of each parameter (``(p_hat - p_true) / std``) shows a
  bias as a mean over seeds away from 0 (standard error ``1 / sqrt(seeds)``);
* ``Delta chi2 = z^T H z`` (``H`` the hat matrix) split into its diagonal ``sum h_i z_i^2``
  (above 7 only when sigma is too small where the parameters are decided), the part between
  channels of one configuration, and the part between configurations (its mean is 0 for
  independent samples, so a positive mean over seeds means correlated errors or a bias);
* the mean ``z_i z_j`` over same-channel pairs of configurations whose measured light directions
  agree within 1 deg (a correlation between configurations sharing a light);
* with ``--weights-every N``, for every N-th configuration, the sample value re-measured from its
  HDR frame (``RUN/hdr/*.exr``: merged rate, variance, pose) twice: with the spot fit's pixels
  weighted by the merge's variance, which the merge evaluates at each pixel's own noisy rate,
  and with the noise model at a locally smoothed rate: the difference, in sigma, is the bias the
  first weights cause. Runs acquired before the spot fit came to weight its pixels at the fitted
  surface (``HDRResult.variance_at``) recorded the first value (``reproduced_max_abs_dz`` is 0
  for them); later runs record a value free of that bias, and this diagnosis is what led to it.

Writes ``benchmarks/results/truth_residual.csv`` (one row per run) and, with
``--weights-every``, ``truth_residual_weights.csv`` (one row per run: mean bias per channel).
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
NAMES = ["albedo_R", "albedo_G", "albedo_B", "alpha", "f0_R", "f0_G", "f0_B"]
P_TRUE = np.array([0.55, 0.22, 0.06, 0.18, 0.05, 0.05, 0.05])  # the built-in paint


def build(p):
    from gonio.brdf import models

    return models.Lambert(albedo=p[0:3]) + models.TorranceSparrow(
        alpha=p[3], distribution="beckmann", shadowing="vcavity",
        fresnel=models.Schlick(f0=p[4:7]),
    )  # fmt: skip


def whitened(run: Path):
    """(samples, truth values (N, 3), whitened Jacobian (3N, 7)) of one run at the truth."""
    from gonio import io

    s = io.load(run / "table.brdf.h5")
    wi, wo = np.asarray(s.wi), np.asarray(s.wo)
    f = np.asarray(build(P_TRUE).f(wi, wo))
    eps = 1e-7
    jac = np.stack([(np.asarray(build(P_TRUE + eps * np.eye(7)[i]).f(wi, wo)) - f) / eps
                    for i in range(7)], -1)  # fmt: skip
    return s, f, (jac / np.asarray(s.sigma)[..., None]).reshape(-1, 7)


def decompose(run: Path) -> dict:
    """The linearized decomposition of one run (see the module docstring)."""
    s, f, jw = whitened(run)
    wi = np.asarray(s.wi)
    v, sg = np.asarray(s.values), np.asarray(s.sigma)
    z = ((v - f) / sg).ravel()
    a = jw.T @ jw
    cov = np.linalg.inv(a)
    dp = cov @ (jw.T @ z)
    u = np.linalg.cholesky(a).T @ dp
    h = jw @ cov @ jw.T
    n = len(v)
    cfg = np.repeat(np.arange(n), v.shape[1])
    same_cfg = cfg[:, None] == cfg[None, :]
    zz = h * np.outer(z, z)
    diag = float(np.trace(zz))
    cross_channel = float(zz[same_cfg].sum()) - diag
    # the correlation reported earlier between configurations sharing a light: pairs whose
    # measured light directions agree within 1 deg, same channel; mean of z_i z_j (0 +- about
    # 1 / sqrt(pairs) for independent samples)
    cos1 = np.cos(np.radians(1.0))
    near = (wi @ wi.T > cos1) & ~np.eye(n, dtype=bool)
    zc = z.reshape(n, -1)
    prods = (zc[:, None, :] * zc[None, :, :])[np.triu(near, 1)]
    row = {
        "values": int(z.size),
        "light_pairs": int(prods.size),
        "light_pair_corr": float(prods.mean()) if prods.size else float("nan"),
        "delta_chi2_lin": float(u @ u),
        "diag": diag,
        "cross_channel": cross_channel,
        "cross_config": float(zz.sum()) - diag - cross_channel,
        "mean_z": float(z.mean()),
    }
    row.update({f"z_{k}": float(x) for k, x in zip(NAMES, dp / np.sqrt(np.diag(cov)), strict=True)})
    row.update({f"u{i}": float(x) for i, x in enumerate(u)})
    return row


def weights_bias(run: Path, every: int) -> dict:
    """Mean (smooth-weight value - recorded value) / sigma per channel over every ``every``-th
    configuration's HDR frame, with its standard error."""
    import OpenEXR
    from scipy import ndimage

    from gonio.acquire.radiometry import measure_brdf
    from gonio.io.exr import read_exr
    from gonio.rigs.config import load_rig
    from gonio.rigs.sim.camera import HolderLayout, PinholeCamera
    from gonio.rigs.sim.sensor import SensorModel

    rig = load_rig(str(run.parent / "rig.toml"))
    c = rig.camera
    k = PinholeCamera(int(c["width"]), int(c["height"]), float(c["focal_px"])).matrix
    lay = HolderLayout()
    out, repro = [], 0.0
    for exr in sorted((run / "hdr").glob("c*.exr"))[::every]:
        img, _ = read_exr(exr)
        with OpenEXR.File(str(exr)) as fh:
            hd = fh.header()
            rot = np.array(json.loads(hd["gonio_pose_R"]))
            t = np.array(json.loads(hd["gonio_pose_t_m"]))
            light = np.array(json.loads(hd["gonio_light_pos_m"]))
            f_rec = np.array(json.loads(hd["gonio_f"]))
            s_rec = np.array(json.loads(hd["gonio_sigma"]))
        rate = img[..., 3].astype(np.float64)
        var = img[..., 4].astype(np.float64) ** 2
        plane = SensorModel(**dict(c.get("sensor", {}))).plane_index(rate.shape)
        args = (plane, k, rot, t, light, lay.sample_center, lay.sample_radius,
                lay.reference_center, lay.reference_radius, lay.reference_albedo)  # fmt: skip
        kw = {"spot_radius": float(c.get("spot_radius_m", 0.002)), "fit_order": 2}
        own = measure_brdf(rate, var, *args, **kw).f
        repro = max(repro, float(np.max(np.abs(own - f_rec) / s_rec)))
        smooth = np.zeros_like(rate)
        for ch in range(3):
            sel = plane == ch
            num = ndimage.uniform_filter(np.where(sel, rate, 0.0), 7)
            den = ndimage.uniform_filter(sel.astype(float), 7)
            smooth = np.where(sel, num / np.maximum(den, 1e-12), smooth)
        pos = rate > 0
        var_s = var * np.where(pos, smooth / np.where(pos, rate, 1.0), 1.0)
        out.append((measure_brdf(rate, var_s, *args, **kw).f - own) / s_rec)
    d = np.array(out)
    row = {"configs": len(d), "reproduced_max_abs_dz": repro}
    for ch, name in enumerate("RGB"):
        row[f"bias_{name}"] = float(d[:, ch].mean())
        row[f"sem_{name}"] = float(d[:, ch].std(ddof=1) / np.sqrt(len(d)))
    # what that bias does to the fit if every sample of the run carries it (values in sigma
    # lowered by the mean per channel): the parameters' shift in std and its Delta chi2
    _, f, jw = whitened(run)
    b = -np.tile(d.mean(axis=0), len(f))
    a = jw.T @ jw
    dp = np.linalg.solve(a, jw.T @ b)
    zshift = dp / np.sqrt(np.diag(np.linalg.inv(a)))
    row.update({f"shift_z_{k}": float(x) for k, x in zip(NAMES, zshift, strict=True)})
    row["shift_delta_chi2"] = float(dp @ a @ dp)
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", type=Path, required=True, help="bench_truth_check's --workdir")
    ap.add_argument("--seeds", type=int, nargs="+", required=True)
    ap.add_argument("--plan", default="demo")
    ap.add_argument("--weights-every", type=int, default=0, metavar="N")
    ap.add_argument("--weights-seeds", type=int, nargs="*", default=None,
                    help="seeds for --weights-every (default: all)")  # fmt: skip
    args = ap.parse_args(argv)
    RESULTS.mkdir(exist_ok=True)
    rows = []
    for seed in args.seeds:
        run = args.workdir / f"seed{seed}-{args.plan}" / "run"
        if not (run / "table.brdf.h5").is_file():
            print(f"gonio: {run}: no table (acquire it with bench_truth_check.py)", file=sys.stderr)
            return 2
        rows.append({"seed": seed, **decompose(run)})
        r = rows[-1]
        print(f"seed {seed}: delta chi2 {r['delta_chi2_lin']:.1f} = diag {r['diag']:.1f}"
              f" + channels {r['cross_channel']:.1f} + configurations {r['cross_config']:.1f}",
              flush=True)  # fmt: skip
    with open(RESULTS / "truth_residual.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    n = len(rows)

    def mean_sem(key):
        x = np.array([r[key] for r in rows])
        return x.mean(), (x.std(ddof=1) / np.sqrt(n) if n > 1 else float("nan"))

    for key in ("delta_chi2_lin", "diag", "cross_channel", "cross_config", "light_pair_corr"):
        m, e = mean_sem(key)
        print(f"{key}: {m:.2f} +- {e:.2f}")
    print("signed parameter z, mean over seeds (standard error %.2f):" % (1 / np.sqrt(n)))
    print("  " + ", ".join(f"{k} {mean_sem('z_' + k)[0]:+.2f}" for k in NAMES))
    u = np.array([[r[f"u{i}"] for i in range(7)] for r in rows])
    mu = u.mean(0)
    print(
        f"|mean u|^2 {mu @ mu:.2f} (noise alone: {7 / n:.2f}); mean |u - mean u|^2"
        f" {np.mean(np.sum((u - mu) ** 2, 1)):.2f} (noise alone: {7 * (n - 1) / n:.2f})"
    )
    if args.weights_every:
        wrows = []
        for seed in args.weights_seeds or args.seeds:
            run = args.workdir / f"seed{seed}-{args.plan}" / "run"
            wrows.append({"seed": seed, **weights_bias(run, args.weights_every)})
            r = wrows[-1]
            bias = ", ".join(f"{-r['bias_' + c]:+.3f} +- {r['sem_' + c]:.3f}" for c in "RGB")
            shift = ", ".join(f"{k} {r['shift_z_' + k]:+.2f}" for k in NAMES)
            print(f"seed {seed}: own-rate pixel weights bias f by {bias} sigma (R, G, B;"
                  f" {r['configs']} configurations); as a uniform bias it shifts the parameters"
                  f" by {shift} std and adds {r['shift_delta_chi2']:.2f} to Delta chi2",
                  flush=True)  # fmt: skip
        with open(RESULTS / "truth_residual_weights.csv", "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(wrows[0]))
            w.writeheader()
            w.writerows(wrows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
