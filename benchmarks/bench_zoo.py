"""Throughput of the zoo models next to the core models, and HTSG's cost versus accuracy.

Part 1: ``f``, ``pdf`` and ``sample`` at a batch of 1e6 directions, float32, under ``jax.jit``
(best of ``--repeats`` after a warm-up call; compile time excluded), for every model available in
``gonio.brdf.models``.

Part 2: HTSG directional-diffuse evaluation with M = 2 .. 128 series terms: throughput
(float32, jitted, batch ``--htsg-batch``) and the error of ``f`` against a 2048-term reference
(float64, 4096 direction pairs, half near the mirror direction) for a smooth, a medium and a
rough surface.

Writes ``benchmarks/results/bench_zoo_throughput.csv``, ``bench_zoo_htsg_terms.csv`` and
``bench_zoo_htsg_terms.png``.

    PYTHONPATH=src python benchmarks/bench_zoo.py [--batch 1000000] [--repeats 3]
"""

from __future__ import annotations

import argparse
import csv
import os
import platform
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from gonio.brdf import frames, models

RESULTS = Path(__file__).resolve().parent / "results"


def _directions(n: int, seed: int, dtype) -> jnp.ndarray:
    rng = np.random.default_rng(seed)
    th = rng.uniform(0, np.pi / 2 * 0.999, n)
    ph = rng.uniform(0, 2 * np.pi, n)
    return jnp.asarray(np.asarray(frames.spherical_to_direction(th, ph)), dtype)


def _time(fn, *args, repeats: int) -> float:
    jax.block_until_ready(fn(*args))  # compile + warm up
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        best = min(best, time.perf_counter() - t0)
    return best


def _candidates():
    """(label, model) pairs: core models when present, then the zoo."""
    m = models
    out = [("Lambert", m.Lambert([0.5, 0.4, 0.3]))]
    if hasattr(m, "Phong"):
        out.append(("Phong", m.Phong(rho_d=[0.2, 0.3, 0.4], rho_s=0.5, n=50.0)))
    if hasattr(m, "BlinnPhong"):
        out.append(("BlinnPhong", m.BlinnPhong(rho_d=[0.2, 0.3, 0.4], rho_s=0.5, n=50.0)))
    if hasattr(m, "Ward"):
        out.append(("Ward", m.Ward(rho_d=[0.2, 0.3, 0.4], rho_s=0.1, alpha_x=0.1, alpha_y=0.3)))
    if hasattr(m, "TorranceSparrow") and hasattr(m, "Conductor"):
        out.append(
            (
                "TorranceSparrow(ggx,smith,conductor)",
                m.TorranceSparrow(
                    alpha=0.2,
                    distribution="ggx",
                    shadowing="smith",
                    fresnel=m.Conductor(eta=[0.2, 0.9, 1.1], k=[3.9, 2.4, 1.9]),
                ),
            )
        )
    out.append(("Lafortune(1 lobe)", m.Lafortune(n=30.0, rho_s=[[0.5, 0.4, 0.3]], rho_d=0.1)))
    out.append(
        (
            "Lafortune(3 lobes)",
            m.Lafortune(
                cx=[-1.0, 0.6, -0.9],
                cy=[-1.0, 0.6, -0.3],
                cz=[1.0, 0.7, 1.1],
                n=[200.0, 4.0, 15.0],
                rho_s=[[0.3, 0.2, 0.1], [0.1, 0.12, 0.14], [0.2, 0.2, 0.2]],
                rho_d=[0.1, 0.2, 0.3],
            ),
        )
    )
    out.append(
        ("AshikhminShirley", m.AshikhminShirley(rho_d=[0.3, 0.2, 0.1], rho_s=0.05, nu=200, nv=20))
    )
    if hasattr(m, "HTSG"):
        for terms in (24, 48):
            out.append(
                (
                    f"HTSG(M={terms})",
                    m.HTSG(sigma0=0.15, tau=3.0, rho_ud=0.05, fresnel=_alu(), terms=terms),
                )
            )
    return out


def _alu():
    return models.Conductor(eta=[1.2, 0.96, 0.62], k=[7.3, 6.7, 5.4])


def throughput(batch: int, repeats: int) -> list[dict]:
    wi = _directions(batch, 1, jnp.float32)
    wo = _directions(batch, 2, jnp.float32)
    u = jnp.asarray(np.random.default_rng(3).random((batch, 2)), jnp.float32)
    f = jax.jit(lambda m, a, b: m.f(a, b))
    pdf = jax.jit(lambda m, a, b: m.pdf(a, b))
    sample = jax.jit(lambda m, w, uu: m.sample(w, uu))
    rows = []
    for label, model in _candidates():
        row = {"model": label, "batch": batch}
        for name, fn, args in (
            ("f", f, (model, wi, wo)),
            ("pdf", pdf, (model, wi, wo)),
            ("sample", sample, (model, wo, u)),
        ):
            t = _time(fn, *args, repeats=repeats)
            row[f"{name}_Mps"] = round(batch / t / 1e6, 3)
        print(row, flush=True)
        rows.append(row)
    return rows


def htsg_terms(batch: int, repeats: int) -> list[dict]:
    n_err = 4096
    wi64 = _directions(n_err, 11, jnp.float64)
    wo64 = _directions(n_err, 12, jnp.float64)
    # half of the error set near the mirror direction, where the directional lobe lives
    rng = np.random.default_rng(13)
    near = np.asarray(wo64[: n_err // 2]) * [-1, -1, 1] + rng.normal(0, 0.1, (n_err // 2, 3))
    near[:, 2] = np.abs(near[:, 2]) + 1e-3
    near /= np.linalg.norm(near, axis=-1, keepdims=True)
    wi64 = wi64.at[: n_err // 2].set(jnp.asarray(near))
    wi32 = _directions(batch, 14, jnp.float32)
    wo32 = _directions(batch, 15, jnp.float32)
    dd = jax.jit(lambda m, a, b: m.directional_diffuse(a, b))
    surfaces = {"smooth (sigma0=0.05um)": 0.05, "medium (0.2um)": 0.2, "rough (0.8um)": 0.8}
    rows = []
    for label, s0 in surfaces.items():
        ref_model = models.HTSG(sigma0=s0, tau=3.0, fresnel=_alu(), terms=2048)
        ref = np.concatenate(
            [
                np.asarray(dd(ref_model, wi64[i : i + 256], wo64[i : i + 256]))
                for i in range(0, n_err, 256)
            ]
        )
        scale = ref.max()
        for terms in (2, 4, 8, 12, 16, 24, 32, 48, 64, 128):
            m = models.HTSG(sigma0=s0, tau=3.0, fresnel=_alu(), terms=terms)
            got = np.asarray(dd(m, wi64, wo64))
            rel = np.abs(got - ref) / np.maximum(ref, 1e-3 * scale)
            t = _time(dd, m, wi32, wo32, repeats=repeats)
            row = {
                "surface": label,
                "terms": terms,
                "Meval_per_s": round(batch / t / 1e6, 3),
                "max_rel_err": float(f"{rel.max():.3g}"),
                "median_rel_err": float(f"{np.median(rel):.3g}"),
            }
            print(row, flush=True)
            rows.append(row)
    return rows


def _write(rows: list[dict], path: Path) -> None:
    tmp = path.with_suffix(path.suffix + ".tmp")
    with open(tmp, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    os.replace(tmp, path)


def _markdown(rows: list[dict]) -> str:
    keys = list(rows[0])
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    lines += ["| " + " | ".join(str(r[k]) for k in keys) + " |" for r in rows]
    return "\n".join(lines)


def _plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
    for surface in dict.fromkeys(r["surface"] for r in rows):
        rr = [r for r in rows if r["surface"] == surface]
        terms = [r["terms"] for r in rr]
        a1.loglog(terms, [max(r["max_rel_err"], 1e-17) for r in rr], "o-", label=surface)
        a2.semilogx(terms, [r["Meval_per_s"] for r in rr], "o-", label=surface)
    a1.set_xlabel("series terms M")
    a1.set_ylabel("max relative error of f (vs 2048 terms)")
    a2.set_xlabel("series terms M")
    a2.set_ylabel("M evaluations / s (float32, jitted)")
    a1.legend()
    a1.grid(True, which="both", alpha=0.3)
    a2.grid(True, which="both", alpha=0.3)
    fig.suptitle(f"HTSG directional diffuse: cost vs accuracy ({platform.processor() or 'cpu'})")
    fig.tight_layout()
    tmp = path.with_name(path.stem + ".tmp.png")
    fig.savefig(tmp, dpi=120)
    os.replace(tmp, path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--batch", type=int, default=1_000_000, help="directions per call")
    ap.add_argument("--repeats", type=int, default=3, help="timed calls per case (best kept)")
    ap.add_argument(
        "--htsg-batch", type=int, default=262_144, help="directions per call in the HTSG study"
    )
    ap.add_argument("--skip-throughput", action="store_true", help="only the HTSG study")
    args = ap.parse_args()
    RESULTS.mkdir(parents=True, exist_ok=True)
    print(f"devices: {jax.devices()}, cpus: {os.cpu_count()}, load: {os.getloadavg()}")
    if not args.skip_throughput:
        rows = throughput(args.batch, args.repeats)
        _write(rows, RESULTS / "bench_zoo_throughput.csv")
        print(_markdown(rows))
    if hasattr(models, "HTSG"):
        rows = htsg_terms(args.htsg_batch, args.repeats)
        _write(rows, RESULTS / "bench_zoo_htsg_terms.csv")
        _plot(rows, RESULTS / "bench_zoo_htsg_terms.png")
        print(_markdown(rows))


def write_tables() -> None:
    """Rewrite this benchmark's tables in benchmarks/README.md from its CSVs."""
    import _tables

    throughput = [
        ("model", "model"),
        ("f (M/s)", "f_Mps"),
        ("pdf (M/s)", "pdf_Mps"),
        ("sample (M/s)", "sample_Mps"),
    ]
    rows = _tables.read("bench_zoo_throughput.csv")
    _tables.write("zoo_throughput", _tables.markdown(rows, throughput))
    terms = [
        ("surface", "surface"),
        ("terms M", "terms"),
        ("M evaluations/s", "Meval_per_s"),
        ("max rel. error", "max_rel_err"),
        ("median rel. error", "median_rel_err"),
    ]
    rows = _tables.read("bench_zoo_htsg_terms.csv")
    _tables.write("zoo_htsg_terms", _tables.markdown(rows, terms))


if __name__ == "__main__":
    main()
    write_tables()
