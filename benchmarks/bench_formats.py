"""Native .brdf.h5 storage vs the MERL binary: size, error, write/read and partial-read time.

Content: a MERL-resolution (90 x 90 x 180, RGB) table of Lambert + Torrance-Sparrow (Beckmann
distribution, alpha = 0.15, Schlick Fresnel f0 = 0.04, V-cavity shadowing) with multiplicative
Gaussian measurement noise (0.5 %, 1 %, 2 %), tabulated at MERL's nodes; cells below the horizon
are invalid, as in MERL. For each noise level the table is written as a MERL binary (the 35 MB
reference), as lossless .brdf.h5 and as lossy .brdf.h5 at several guaranteed precisions.

Writes benchmarks/results/bench_formats.csv and bench_formats.png.
Run: PYTHONPATH=src python benchmarks/bench_formats.py [--quick]
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import tempfile
import time
from functools import partial
from pathlib import Path

import numpy as np

from gonio.brdf import frames
from gonio.brdf.tabulated import Channels, TabulatedBRDF
from gonio.io import load, merl, native

RESULTS = Path(__file__).resolve().parent / "results"


def realistic_table(noise: float, seed: int = 0) -> TabulatedBRDF:
    """Lambert + Torrance-Sparrow on MERL's grid, with multiplicative noise (see module doc)."""
    axes = merl.merl_axes()
    th, td, pd = np.meshgrid(*(a.nodes() for a in axes), indexing="ij")
    wi, wo = (np.asarray(w) for w in frames.half_diff_to_directions(th, 0 * th, td, pd))
    mask = (wi[..., 2] > 1e-6) & (wo[..., 2] > 1e-6)
    ci, co = np.clip(wi[..., 2], 1e-6, None), np.clip(wo[..., 2], 1e-6, None)
    ch, cd = np.cos(th), np.cos(td)
    a2 = 0.15**2
    d = np.exp(-(np.tan(th) ** 2) / a2) / (math.pi * a2 * ch**4)
    g = np.minimum(1.0, np.minimum(2 * ch * co / cd, 2 * ch * ci / cd))
    f = 0.04 + 0.96 * (1 - cd) ** 5
    spec = d * g * f / (4 * ci * co)
    diffuse = np.array([0.55, 0.30, 0.12]) / math.pi
    v = diffuse + spec[..., None]
    rng = np.random.default_rng(seed)
    v = v * (1 + noise * rng.standard_normal(v.shape))
    v = np.where(mask[..., None], np.maximum(v, 0), 0).astype(np.float32)
    return TabulatedBRDF(
        values=v,
        axes=axes,
        parameterization="half_diff_iso",
        mask=mask,
        channels=Channels.rgb(),
        meta={"source": {"format": "synthetic", "noise": noise}},
    )


def timed(fn, repeat: int = 3) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def run(noises: list[float], precisions: list[float], repeat: int) -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for noise in noises:
            t = realistic_table(noise)
            valid = t.mask
            ref = t.values.astype(np.float64)
            mpath = Path(tmp) / "t.binary"
            merl.write_merl(t, mpath)
            merl_size = os.path.getsize(mpath)
            tw, _ = timed(partial(merl.write_merl, t, mpath), repeat)
            tr, _ = timed(partial(merl.read_merl_arrays, mpath), repeat)
            rows.append(
                dict(
                    noise=noise,
                    encoding="merl-binary",
                    precision="",
                    size=merl_size,
                    ratio_vs_merl=1.0,
                    median_rel=0.0,
                    p99_rel=0.0,
                    max_rel=0.0,
                    write_s=tw,
                    read_s=tr,
                    values_read_s=tr,
                    partial_read_s=float("nan"),
                )
            )
            for lossy in [None, *precisions]:
                p = Path(tmp) / "t.brdf.h5"
                tw, _ = timed(partial(native.write_native, t, p, lossy=lossy), repeat)
                tr, back = timed(partial(load, p), repeat)
                tf, _ = timed(partial(native.read_values, p), repeat)
                tp, part = timed(
                    partial(native.read_values, p, rows=slice(20, 30), channel=1), repeat
                )
                assert part.shape == (10, 90, 180, 1)
                d = back.values.astype(np.float64)
                sel = np.broadcast_to(valid[..., None], ref.shape) & (ref > 0)
                rel = np.abs(d[sel] - ref[sel]) / ref[sel]
                size = os.path.getsize(p)
                rows.append(
                    dict(
                        noise=noise,
                        encoding="lossless" if lossy is None else "lossy",
                        precision="" if lossy is None else lossy,
                        size=size,
                        ratio_vs_merl=merl_size / size,
                        median_rel=float(np.median(rel)),
                        p99_rel=float(np.percentile(rel, 99)),
                        max_rel=float(rel.max()),
                        write_s=tw,
                        read_s=tr,
                        values_read_s=tf,
                        partial_read_s=tp,
                    )
                )
                print(rows[-1])
    return rows


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    for noise in sorted({r["noise"] for r in rows}):
        lossy = [r for r in rows if r["noise"] == noise and r["encoding"] == "lossy"]
        ax[0].plot(
            [r["median_rel"] * 100 for r in lossy],
            [r["ratio_vs_merl"] for r in lossy],
            "o-",
            label=f"lossy, noise {noise:.1%}",
        )
        ll = next(r for r in rows if r["noise"] == noise and r["encoding"] == "lossless")
        ax[0].scatter([0], [ll["ratio_vs_merl"]], marker="s")
        ax[1].bar(f"{noise:.1%}\nall values", ll["values_read_s"], color="C0")
        ax[1].bar(f"{noise:.1%}\n10 rows, 1 ch", ll["partial_read_s"], color="C1")
    ax[0].axhline(30, ls="--", c="gray", lw=0.8)
    ax[0].axhline(3, ls=":", c="gray", lw=0.8)
    ax[0].axvline(0.5, ls="--", c="gray", lw=0.8)
    ax[0].set_xlabel("median relative error (%)")
    ax[0].set_ylabel("size reduction vs MERL binary (x)")
    ax[0].set_yscale("log")
    ax[0].legend(fontsize=8)
    ax[0].set_title("size vs error (squares: lossless)")
    ax[1].set_ylabel("read time, lossless (s)")
    ax[1].set_title("full vs partial read")
    ax[1].tick_params(axis="x", labelsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def markdown(rows: list[dict]) -> str:
    """The results as a Markdown table."""
    out = [
        "| noise | encoding | precision | size (MB) | vs MERL | median err | p99 err | max err "
        "| write (s) | read table (s) | read values (s) | 10 rows, 1 ch (s) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        prec = f"{r['precision']:.1%}" if r["precision"] != "" else ""
        out.append(
            f"| {r['noise']:.1%} | {r['encoding']} | {prec} | {r['size'] / 1e6:.2f} "
            f"| {r['ratio_vs_merl']:.1f}x | {r['median_rel']:.3%} | {r['p99_rel']:.3%} "
            f"| {r['max_rel']:.3%} | {r['write_s']:.2f} | {r['read_s']:.2f} "
            f"| {r['values_read_s']:.3f} | {r['partial_read_s']:.3f} |"
        )
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one noise level, one repeat")
    args = ap.parse_args()
    noises = [0.01] if args.quick else [0.005, 0.01, 0.02]
    rows = run(noises, [0.005, 0.009, 0.02], repeat=1 if args.quick else 3)
    RESULTS.mkdir(parents=True, exist_ok=True)
    with open(RESULTS / "bench_formats.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    plot(rows, RESULTS / "bench_formats.png")
    print(markdown(rows))
    print("wrote", RESULTS / "bench_formats.csv", RESULTS / "bench_formats.png")


def write_tables() -> None:
    """Rewrite this benchmark's table in benchmarks/README.md from its CSV."""
    import _tables

    columns = [
        ("noise", "noise"),
        ("encoding", "encoding"),
        ("precision", "precision"),
        ("bytes", "size"),
        ("x smaller than MERL", "ratio_vs_merl"),
        ("median rel. error", "median_rel"),
        ("p99 rel. error", "p99_rel"),
        ("max rel. error", "max_rel"),
        ("write (s)", "write_s"),
        ("read (s)", "read_s"),
        ("partial read (s)", "partial_read_s"),
    ]
    _tables.write("formats", _tables.markdown(_tables.read("bench_formats.csv"), columns))


if __name__ == "__main__":
    main()
    write_tables()
