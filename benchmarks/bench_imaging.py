"""Imaging benchmarks: HDR merge vs OpenCV's Debevec merge; time per configuration.

Writes CSV + PNG into benchmarks/results/:

* ``imaging_merge.csv/.png`` — the same raw brackets of a virtual-camera frame (a glossy sample,
  the white reference and the ChArUco board, dark frames subtracted) merged by
  :func:`gonio.acquire.hdr.merge_brackets` and by ``cv2.createMergeDebevec``. OpenCV's merge
  takes 8-bit images, so each bracket is demosaicked (``COLOR_BayerRGGB2RGB``) and scaled from
  the sensor's range to 0..255, with the true (linear) camera response given to it. Both results
  are compared per pixel with the noise-free rate at the pixel's own Bayer site (Debevec's output
  scale fitted by least squares, a favour to it) in units of the noise model's sigma of the
  optimal merge: RMS z = 1 is the best any unbiased merge of these brackets can do.
* ``imaging_time_split.csv/.png`` — a simulated acquisition (rig ``sim``) with exposure planning
  from the previous frame and with fixed brackets: per configuration the motion and settle time
  (motion: rig time of the move under the joints' motion profiles between the read-back poses;
  settle: the driver's settle polling scaled to rig time, the emulator running ``time_scale``
  times faster than the rig it simulates), the exposure (sum of shutter times, dark frames
  included), the camera backend's CPU time (rendering and DNG writing for the simulator) and the
  processing CPU time (decode, merge, pose, radiometry, EXR); wall times are in the CSV too (the
  host is shared, so they are noisy). With the number of brackets and the value error |z|.

Run: ``PYTHONPATH=src python benchmarks/bench_imaging.py [--quick]``. Wall times on a shared
machine are noisy; compare the two modes of one run.
"""

from __future__ import annotations

import argparse
import csv
import json
import tempfile
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from gonio.acquire.engine import acquire
from gonio.acquire.hdr import Bracket, NoiseModel, merge_brackets
from gonio.acquire.imaging import demosaic
from gonio.acquire.journal import Journal
from gonio.brdf import models
from gonio.rigs.config import load_rig, parse_rig
from gonio.rigs.sim.camera import CameraPose, PinholeCamera, VirtualCamera
from gonio.rigs.sim.sensor import SensorModel

OUT = Path(__file__).resolve().parent / "results"


def bench_merge(quick: bool) -> list[dict]:
    import cv2

    sensor = SensorModel()
    truth = models.Lambert([0.2, 0.15, 0.1]) + models.Phong(rho_d=0.0, rho_s=0.5, n=60.0)
    cam = VirtualCamera(truth=truth, camera=PinholeCamera(480, 360, 1800.0), sensor=sensor, seed=3)
    d = 0.6
    light = d * np.array([np.sin(np.radians(30)), 0.0, np.cos(np.radians(30))])
    cpos = 0.8 * np.array([-np.sin(np.radians(30)), 0.0, np.cos(np.radians(30))])
    rate = sensor.mosaic(cam.electron_rate(CameraPose.looking_at_origin(cpos), light, 3.6))
    noise = NoiseModel(sensor.gain, sensor.read_noise, sensor.dark_current)
    rows = []
    sets = {
        "3 brackets, 8x": [2e-4, 1.6e-3, 1.28e-2],
        "5 brackets, 4x": [1e-4, 4e-4, 1.6e-3, 6.4e-3, 2.56e-2],
    }
    if quick:
        sets = dict(list(sets.items())[:1])
    for name, times in sets.items():
        light_dn = [sensor.expose(rate, t, seed=1, key=f"l{t}")[0] for t in times]
        dark_dn = [sensor.expose(0 * rate, t, seed=2, key=f"d{t}")[0] for t in times]
        brackets = [
            Bracket(dn, t, float(sensor.black_level), sensor.white_level)
            for dn, t in zip(light_dn, times, strict=True)
        ]
        t0 = time.perf_counter()
        res = merge_brackets(brackets, noise, dark=dark_dn)
        t_ours = time.perf_counter() - t0
        want = sensor.gain * rate  # DN/s without dark current (removed by the dark frames)
        ok = np.isfinite(res.rate) & (want > 0) & (res.sigma > 0)
        z_ours = (res.rate - want) / res.sigma
        # OpenCV: 8-bit demosaicked brackets, linear response
        span = sensor.white_level - sensor.black_level
        imgs = []
        for dn, dk in zip(light_dn, dark_dn, strict=True):
            sig = np.clip(dn.astype(float) - dk.astype(float), 0, span)
            rgb = demosaic(sig, sensor.cfa)
            imgs.append(np.clip(rgb / span * 255 + 0.5, 0, 255).astype(np.uint8))
        response = np.tile(np.linspace(1e-3, 1.0, 256, dtype=np.float32)[:, None, None], (1, 1, 3))
        t0 = time.perf_counter()
        hdr = cv2.createMergeDebevec().process(imgs, np.asarray(times, dtype=np.float32), response)
        t_cv = time.perf_counter() - t0
        plane = sensor.plane_index(rate.shape)
        deb = np.take_along_axis(hdr, plane[..., None], axis=-1)[..., 0].astype(float)
        good = ok & np.isfinite(deb)
        scale = float(np.sum(deb[good] * want[good]) / np.sum(deb[good] ** 2))
        z_cv = (deb * scale - want) / res.sigma
        for method, z, t in (("gonio merge (raw, t^2/var)", z_ours, t_ours),
                             ("OpenCV Debevec (8-bit, demosaicked)", z_cv, t_cv)):  # fmt: skip
            zz = z[good]
            rows.append(
                {
                    "brackets": name,
                    "method": method,
                    "rms_z": float(np.sqrt(np.mean(zz**2))),
                    "median_abs_z": float(np.median(np.abs(zz))),
                    "p95_abs_z": float(np.percentile(np.abs(zz), 95)),
                    "pixels": int(good.sum()),
                    "time_s": t,
                }
            )
    return rows


def _small_rig(planning: bool):
    text = load_rig("sim").text
    text = text.replace("width = 640", "width = 480").replace("height = 480", "height = 360")
    text = text.replace("focal_px = 2400.0", "focal_px = 1800.0")
    text = text.replace(
        "spot_radius_m = 0.002", f"spot_radius_m = 0.002\nplanning = {str(planning).lower()}"
    )
    return parse_rig(text, "sim-bench.toml")


PLAN = """kind = "isotropic"
theta_i_deg = [20, 45]
theta_o_deg = [20, 45, 60]
dphi_deg = [180]
"""


def bench_time_split(quick: bool) -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        plan = Path(tmp) / "plan.toml"
        plan.write_text(PLAN if not quick else PLAN.replace("[20, 45, 60]", "[20, 45]"))
        # warm-up (imports, JAX compilations of the sample's BRDF for the shapes these
        # geometries need) outside the timed runs, so that neither mode pays them
        acquire(Path(tmp) / "warm", _small_rig(True), plan, progress=False)
        for planning in (True, False):
            rig = _small_rig(planning)
            scale = rig.sim.time_scale
            run = Path(tmp) / f"run-{planning}"
            acquire(run, rig, plan, progress=False)
            truth = models.Node.from_dict(rig.sim.sample)
            j = Journal(run)
            samples = {s.idx: s for s in j.samples()}
            seq = [c.idx for c in j.configs() if c.status == "planned"]
            j.close()
            motion = _profile_motion(rig, [samples[i].joints_deg for i in seq])
            for line in (run / "log.jsonl").read_text().splitlines():
                e = json.loads(line)
                if e["event"] != "sample":
                    continue
                s = samples[e["idx"]]
                f = np.asarray(truth.f(s.wi, s.wo))
                rows.append(
                    {
                        "planning": planning,
                        "idx": e["idx"],
                        "motion_s": motion[seq.index(e["idx"])],
                        # the emulator runs time_scale x faster than the rig it simulates
                        "settle_s": e["t_settle"] * scale,
                        "exposure_s": e.get("t_exposure", 0.0),
                        "camera_s": e.get("t_camera_cpu", 0.0),
                        "processing_s": e.get("t_processing_cpu", 0.0),
                        "camera_wall_s": e.get("t_camera", 0.0),
                        "processing_wall_s": e.get("t_processing", 0.0),
                        "brackets": len(_exposures(run, e["idx"])),
                        "max_abs_z": float(np.max(np.abs((s.value - f) / s.sigma))),
                    }
                )
    return rows


def _profile_motion(rig, poses: list[dict]) -> list[float]:
    """Rig time of each move (slowest joint under its trapezoidal profile), from park."""
    prev = dict(rig.park_deg)
    out = []
    for p in poses:
        out.append(
            max(float(j.move_time(p[j.name] - prev.get(j.name, p[j.name]))) for j in rig.joints)
        )
        prev = p
    return out


def _exposures(run: Path, idx: int) -> list[float]:
    import OpenEXR

    with OpenEXR.File(str(run / "hdr" / f"c{idx:05d}.exr")) as f:
        return json.loads(f.header()["gonio_exposures_s"])


def _write_csv(path: Path, rows: list[dict]) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer brackets sets and configurations")
    args = ap.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)

    merge = bench_merge(args.quick)
    _write_csv(OUT / "imaging_merge.csv", merge)
    print("| brackets | method | RMS z | median abs z | p95 abs z | time (s) |")
    print("|---|---|---|---|---|---|")
    for r in merge:
        print(f"| {r['brackets']} | {r['method']} | {r['rms_z']:.3f} | {r['median_abs_z']:.3f} |"
              f" {r['p95_abs_z']:.3f} | {r['time_s']:.3f} |")  # fmt: skip
    fig, ax = plt.subplots(figsize=(7, 4))
    labels = sorted({r["brackets"] for r in merge})
    methods = sorted({r["method"] for r in merge})
    x = np.arange(len(labels))
    for k, m in enumerate(methods):
        vals = [next(r["rms_z"] for r in merge if r["brackets"] == b and r["method"] == m)
                for b in labels]  # fmt: skip
        ax.bar(x + (k - 0.5) * 0.38, vals, 0.38, label=m)
    ax.axhline(1.0, color="k", lw=0.8, ls="--", label="noise model (ideal)")
    ax.set_xticks(x, labels)
    ax.set_yscale("log")
    ax.set_ylabel("RMS error / noise-model sigma")
    ax.set_title("HDR merge error on the same raw brackets")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(OUT / "imaging_merge.png", dpi=120)

    split = bench_time_split(args.quick)
    _write_csv(OUT / "imaging_time_split.csv", split)
    keys = ["motion_s", "settle_s", "exposure_s", "camera_s", "processing_s"]
    print("\n| exposure planning | configs | " + " | ".join(keys) + " | brackets | max abs z |")
    print("|---" * (len(keys) + 4) + "|")
    fig, ax = plt.subplots(figsize=(7, 4))
    for k, planning in enumerate((True, False)):
        rs = [r for r in split if r["planning"] == planning]
        means = [float(np.mean([r[key] for r in rs])) for key in keys]
        nb = float(np.mean([r["brackets"] for r in rs]))
        zmax = float(np.max([r["max_abs_z"] for r in rs]))
        print(f"| {'on' if planning else 'off (fixed)'} | {len(rs)} | "
              + " | ".join(f"{m:.4f}" for m in means) + f" | {nb:.2f} | {zmax:.2f} |")  # fmt: skip
        bottom = 0.0
        for key, m, color in zip(keys, means, plt.cm.tab10.colors, strict=False):
            ax.bar(k, m, 0.6, bottom=bottom, color=color, label=key if k == 0 else None)
            bottom += m
    ax.set_xticks([0, 1], ["planning on", "planning off (fixed brackets)"])
    ax.set_ylabel("seconds per configuration (mean)")
    ax.set_title("Simulated acquisition: time per configuration")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(OUT / "imaging_time_split.png", dpi=120)


def write_tables() -> None:
    """Rewrite this benchmark's tables in benchmarks/README.md from its CSVs."""
    import _tables

    merge = [
        ("brackets", "brackets"),
        ("method", "method"),
        ("RMS z", "rms_z"),
        ("median \\|z\\|", "median_abs_z"),
        ("95th pct \\|z\\|", "p95_abs_z"),
        ("pixels", "pixels"),
        ("time (s)", "time_s"),
    ]
    _tables.write("imaging_merge", _tables.markdown(_tables.read("imaging_merge.csv"), merge))
    split = [
        ("exposure planning", "planning"),
        ("configuration", "idx"),
        ("brackets", "brackets"),
        ("motion (s)", "motion_s"),
        ("settle (s)", "settle_s"),
        ("exposure (s)", "exposure_s"),
        ("camera, CPU (s)", "camera_s"),
        ("processing, CPU (s)", "processing_s"),
        ("max \\|z\\|", "max_abs_z"),
    ]
    rows = _tables.read("imaging_time_split.csv")
    _tables.write("imaging_time_split", _tables.markdown(rows, split))


if __name__ == "__main__":
    main()
    write_tables()
