"""``gonio prior build`` and ``gonio reconstruct``."""

from __future__ import annotations

import argparse
import os
import sys
import time
from typing import Any

from gonio.errors import ParameterError

PRIOR_HELP = "build a material prior (mean + low-rank basis) from a library of BRDF tables"
RECONSTRUCT_HELP = "reconstruct a full table with sigma from sparse samples through a prior"


def register(subparsers: Any) -> None:
    """Add ``gonio prior`` and ``gonio reconstruct`` to the top-level parser."""
    p = subparsers.add_parser(
        "prior",
        help=PRIOR_HELP,
        description="Material priors (gonio.prior): a mean and a low-rank basis of measured "
        "materials in the mapped space m = log(f cos(theta_i) cos(theta_o) + 1e-3) over a "
        "subsampled MERL half/diff grid, with what a Bayesian reconstruction needs. See "
        "docs/guide/prior.md.",
    )
    sub = p.add_subparsers(dest="prior_command", metavar="ACTION")
    b = sub.add_parser(
        "build",
        help="build a prior file from BRDF tables",
        description="Build a *.prior.h5 file from materials: MERL .binary files, native "
        "*.brdf.h5 tables, RGL .bsdf files, neural-BRDF archives (ARCHIVE.zip: all its "
        "materials; ARCHIVE.zip::NAME: one). Each is evaluated at the grid's nodes (90 x 45 x 45 "
        "half/diff cells, MERL's centre nodes), mapped, and the basis is the leading principal "
        "components. Without --rank the rank is chosen by leave-one-material-out: the "
        "smallest whose held-out projection error is within 2%% of the best up to --max-rank.",
    )
    b.add_argument(
        "sources",
        nargs="+",
        metavar="SOURCE",
        help="BRDF file, ARCHIVE.zip or ARCHIVE.zip::NAME (at least 3 materials in all)",
    )
    b.add_argument("--out", required=True, metavar="PRIOR", help="output file (*.prior.h5)")
    b.add_argument(
        "--rank",
        type=int,
        default=None,
        metavar="K",
        help="number of basis vectors (default: chosen by leave-one-out)",
    )
    b.add_argument(
        "--max-rank",
        type=int,
        default=56,
        metavar="N",
        help="largest rank considered (default 56: a file under 100 MB)",
    )
    b.add_argument("--force", action="store_true", help="replace PRIOR if it exists")
    b.add_argument("--json", action="store_true", help="print a JSON summary on stdout")

    def dispatch(args: argparse.Namespace) -> int:
        if args.prior_command == "build":
            return cmd_build(args)
        p.print_help()
        return 0

    p.set_defaults(func=dispatch)

    r = subparsers.add_parser(
        "reconstruct",
        help=RECONSTRUCT_HELP,
        description="Reconstruct a full isotropic table from sparse samples (a run folder's "
        "RUN/table.brdf.h5, or any file gonio reads: a sparse native table's valid nodes, a "
        "scattered file) with a prior: the posterior of the prior's coefficients given the "
        "samples and their sigma (where known), mapped back, with a sigma per cell (delta "
        "method). The output is a native *.brdf.h5 table on the prior's grid that every gonio "
        "command reads; its sigma is correlated across cells, which the file records "
        "(metadata sigma_correlated) and gonio fit honours.",
    )
    r.add_argument("input", metavar="RUN_OR_TABLE", help="run folder or BRDF file")
    r.add_argument("--prior", required=True, metavar="PRIOR", help="a *.prior.h5 file")
    r.add_argument("--out", required=True, metavar="TABLE", help="output table (*.brdf.h5)")
    r.add_argument("--force", action="store_true", help="replace TABLE if it exists")
    r.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    r.set_defaults(func=cmd_reconstruct)


def _check_out(out: str, force: bool, suffixes: tuple[str, ...]) -> None:
    if not out.lower().endswith(suffixes):
        raise ParameterError(f"{out}: the output must end in {' or '.join(suffixes)}")
    if os.path.isdir(out):
        raise ParameterError(f"{out} is a folder; give a file name")
    if os.path.exists(out) and not force:
        raise ParameterError(f"{out} exists (use --force to replace it)")


def _emit(summary: dict, as_json: bool, line: str) -> None:
    if as_json:
        from gonio.io.strict_json import dumps_json

        print(dumps_json(summary, indent=2))
    else:
        print(line, file=sys.stderr)


def cmd_build(args: argparse.Namespace) -> int:
    """Execute ``gonio prior build``."""
    _check_out(args.out, args.force, (".h5", ".hdf5"))
    if args.rank is not None and args.rank < 1:
        raise ParameterError(f"--rank must be >= 1, got {args.rank}")
    if args.max_rank < 1:
        raise ParameterError(f"--max-rank must be >= 1, got {args.max_rank}")
    from gonio.prior.build import build_prior
    from gonio.prior.sources import expand_sources, load_materials

    found = expand_sources(args.sources)
    if len(found) < 3:
        raise ParameterError(f"a prior needs at least 3 materials, the sources hold {len(found)}")
    names = [n for n, _ in found]
    addresses = [a for _, a in found]
    say = None if args.json else (lambda s: print(f"\r{s:<60}", end="", file=sys.stderr))
    t0 = time.perf_counter()
    prior = build_prior(
        load_materials(addresses),
        names,
        args.rank,
        max_rank=args.max_rank,
        sources=addresses,
        progress=say,
    )
    if say is not None:
        print("\r" + " " * 60 + "\r", end="", file=sys.stderr)
    prior.write(args.out)
    size = os.path.getsize(args.out)
    summary = {
        "out": args.out,
        "materials": len(names),
        "rank": prior.rank,
        "valid_cells": prior.n_valid,
        "bytes": size,
        "seconds": round(time.perf_counter() - t0, 1),
        "peak_rss_mib": prior.meta["build"]["peak_rss_mib"],
        "loo_rms_at_rank": prior.meta["rank_selection"]["loo_rms_at_rank"],
    }
    _emit(
        summary,
        args.json,
        f"wrote {args.out}: {len(names)} materials, rank {prior.rank}, "
        f"{prior.n_valid} cells, {size / 2**20:.1f} MiB, {summary['seconds']:.0f} s, "
        f"held-out projection RMS {summary['loo_rms_at_rank']:.3f} (mapped space)",
    )
    return 0


def cmd_reconstruct(args: argparse.Namespace) -> int:
    """Execute ``gonio reconstruct``."""
    _check_out(args.out, args.force, (".h5", ".hdf5"))
    from gonio import io
    from gonio.io.atomic import same_file
    from gonio.prior.model import Prior
    from gonio.prior.sources import read_samples

    if os.path.exists(args.input) and same_file(args.input, args.out):
        raise ParameterError("RUN_OR_TABLE and TABLE are the same file")
    prior = Prior.read(args.prior)
    s = read_samples(args.input)
    if s.values.shape[1] != prior.n_channels:
        raise ParameterError(
            f"{args.input} has {s.values.shape[1]} channels, the prior {prior.n_channels}"
        )
    meta = {
        "source": {
            "reconstructed_from": os.fspath(args.input),
            "prior": os.fspath(args.prior),
            "name": s.meta.get("name"),
        }
    }
    r = prior.reconstruct(s.wi, s.wo, s.values, s.sigma, meta=meta)
    io.save(r.table, args.out)
    summary = {
        "out": args.out,
        "samples": r.n_used,
        "dropped": r.n_dropped,
        "sigma_known": s.sigma is not None,
        "rank": prior.rank,
        "predicted_error": r.predicted_error,
    }
    _emit(
        summary,
        args.json,
        f"wrote {args.out}: {r.n_used} samples ({r.n_dropped} dropped) "
        f"-> {prior.n_valid} cells, predicted mean |error| {r.predicted_error:.3f} in the "
        "mapped space; its sigma is correlated across cells",
    )
    return 0
