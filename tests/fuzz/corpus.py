"""The fuzzing corpus: small real files from ../shared/data and files written by gonio's writers.

Every entry is a :class:`Seed` (a source file and the *kind* of check its mutants get, see
:mod:`tests.fuzz.worker`). Generated files are deterministic (fixed random seeds, a fixed
creation time), so a case ``(master seed, index)`` replays to the same bytes on the same
platform. Real files are used where ``../shared/data`` has them; without that folder the corpus
is the generated part only (RGL then has the files gonio's RGL writer produced).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from unittest import mock

import numpy as np

from tests.conftest import ROOT, SHARED_DATA

#: Kinds of check, one per reader family (the worker's ``CHECKS``).
KINDS = ("native", "merl", "rgl", "nbrdf", "cornell", "alta", "exr", "exr_slices", "rig", "plan",
         "fit", "prior")  # fmt: skip


def has_nbrdf_reader() -> bool:
    """Whether this gonio reads neural-BRDF archives (``gonio.io.nbrdf``); without it the
    corpus has no ``nbrdf`` seeds."""
    import importlib.util

    return importlib.util.find_spec("gonio.io.nbrdf") is not None


#: Real files per kind (relative to ../shared/data); the big ALTA file is left out (1 MB of text
#: per case would dominate the run time; its header and format are those of the small one).
REAL_FILES = {
    "rgl": ["rgl/paper_white_rgb.bsdf", "rgl/acrylic_felt_green_rgb.bsdf"],
    "cornell": ["cornell/acryl_blue.brdf"],
    "alta": ["alta/pink-felt-1d.alta"],
}
SHIPPED_RIGS = ("sim.toml", "sim_sample.toml", "xm430_4axis.toml")
#: The format's example files (written before the checksums: contiguous, unfiltered datasets).
EXAMPLES = ROOT / "data-schema" / "examples"


@dataclass(frozen=True)
class Seed:
    """One corpus file: ``name`` (unique, used in reports), check ``kind`` and ``path``."""

    name: str
    kind: str
    path: Path


def _fixed_time() -> mock._patch:
    """Writers stamp ``created_utc``; a fixed clock makes generated files byte-reproducible."""
    return mock.patch("time.gmtime", return_value=time.gmtime(0))


def _half_diff_table(n: tuple[int, int, int], seed: int, channels: str = "rgb"):
    from gonio.brdf.tabulated import Channels, TabulatedBRDF
    from gonio.io.merl import merl_axes

    rng = np.random.default_rng(seed)
    n_ch = 3 if channels == "rgb" else 1
    values = (0.05 + rng.random((*n, n_ch)) ** 4 * 5).astype(np.float32)
    mask = np.ones(n, bool)
    mask[-1, -1, :] = False  # a few invalid cells, as near the horizon
    ch = Channels.rgb() if channels == "rgb" else Channels.mono()
    return TabulatedBRDF(
        values=values,
        axes=merl_axes(n),
        parameterization="half_diff_iso",
        mask=mask,
        sigma=(values * 0.05).astype(np.float32),
        counts=np.full(n, 3, np.uint32),
        channels=ch,
        meta={"source": {"format": "fuzz-corpus", "seed": seed}},
        interpolation="linear",
    )


def _samples(n: int, seed: int, n_ch: int = 3):
    from gonio.brdf.measured import MeasuredSamples
    from gonio.brdf.tabulated import Channels

    rng = np.random.default_rng(seed)

    def dirs() -> np.ndarray:
        th = np.arccos(np.sqrt(rng.random(n)))
        ph = 2 * math.pi * rng.random(n)
        return np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)

    values = 0.1 + rng.random((n, n_ch))
    return MeasuredSamples(
        wi=dirs(),
        wo=dirs(),
        values=values,
        sigma=0.05 * values,
        channels=Channels.rgb() if n_ch == 3 else Channels.mono(),
        weights=np.ones(n),
        meta={"source": {"format": "fuzz-corpus", "seed": seed}},
    )


def _cornell_text(n: int, seed: int) -> str:
    rng = np.random.default_rng(seed)
    wl = [400, 500, 600, 700]
    lines = ["# fuzz corpus Cornell file", str(len(wl)), " ".join(map(str, wl))]
    for _ in range(n):
        ti, ts = rng.uniform(0.1, 1.4, 2)
        pi_, ps = rng.uniform(-math.pi, math.pi, 2)
        vals = rng.uniform(0.01, 2.0, len(wl))
        lines.append(" ".join(f"{x:.6g}" for x in (ti, pi_, ts, ps, *vals)))
    return "\n".join(lines) + "\n"


def _alta_text(n: int, seed: int) -> str:
    rng = np.random.default_rng(seed)
    lines = [
        "#DIM 3 1",
        "#PARAM_IN ISOTROPIC_TL_TV_PROJ_DPHI",
        "#PARAM_OUT INV_STERADIAN_COSINE_FACTOR",
        "#VS 2",
    ]
    for _ in range(n):
        tl, tv = rng.uniform(0.1, 1.3, 2)
        dphi = rng.uniform(0, math.pi)
        v = rng.uniform(0.01, 3.0)
        lo, hi = 0.9 * v, 1.1 * v
        lines.append(
            " ".join(f"{x:.6g}" for x in (tl, tv * math.cos(dphi), tv * math.sin(dphi), v, lo, hi))
        )
    return "\n".join(lines) + "\n"


def _plans(out: Path) -> list[Seed]:
    import tomli_w

    from gonio.acquire.plans import BUILTIN

    seeds = []
    for name in ("iso-tiny", "grid4d-small", "halfdiff-small", "adaptive-small"):
        p = out / f"{name}.plan.toml"
        p.write_text(tomli_w.dumps(BUILTIN[name]))
        seeds.append(Seed(f"plan:{name}", "plan", p))
    return seeds


def _fit_json(out: Path) -> list[Seed]:
    """Fit results of two small real fits (Lambert, Lambert + Ward) to synthetic samples."""
    from gonio import fit
    from gonio.brdf import models
    from gonio.fit.data import from_arrays

    truth = models.Lambert(albedo=[0.4, 0.3, 0.2]) + models.Ward(
        rho_d=0.0, rho_s=0.1, alpha_x=0.2, alpha_y=0.2
    )
    s = _samples(300, 7)
    data = from_arrays(s.wi, s.wo, np.asarray(truth.f(s.wi, s.wo)), theta_max_deg=80.0)
    seeds = []
    for model in ("lambert", "lambert+ward"):
        res = fit.fit(data, model, n_starts=1, max_iter=30, subsample=300, name="fuzz")
        obj = res.to_json()
        obj["wall_s"] = 1.0  # the only field that changes from run to run
        p = out / f"{model.replace('+', '_')}.fit.json"
        p.write_text(json.dumps(obj, indent=2, allow_nan=False) + "\n")
        seeds.append(Seed(f"fit:{model}", "fit", p))
    return seeds


def _prior_files(out: Path) -> list[Seed]:
    """Two small material priors (``*.prior.h5``): a random orthonormal basis on a coarse grid,
    RGB and mono."""
    from gonio.brdf.grid import Channels
    from gonio.prior import Prior, prior_axes, space

    seeds = []
    for name, C, K in (("rgb", 3, 3), ("mono", 1, 2)):
        rng = np.random.default_rng(11 + C)
        axes = prior_axes(6, 5, 5)
        mask = space.valid_mask(axes)
        V = int(mask.sum())
        B, _ = np.linalg.qr(rng.normal(size=(V * C, K)))
        ch = Channels.rgb() if C == 3 else Channels.mono()
        prior = Prior(axes, mask, rng.normal(-2.0, 0.5, (V, C)), B.reshape(V, C, K),
                      np.linspace(2.0, 0.5, K), np.full((V, C), 0.01), ch,
                      meta={"materials": ["a", "b", "c"]})  # fmt: skip
        p = out / f"{name}.prior.h5"
        prior.write(p)
        seeds.append(Seed(f"prior:{name}", "prior", p))
    return seeds


def _rgl_written(out: Path) -> list[Seed]:
    """RGL tensor files written by gonio's writer (:mod:`gonio.io.rgl_write`) from two analytic
    models: a Lambert + rough Torrance-Sparrow (RGB) and a grey Lambert (one colour channel)."""
    from gonio import io
    from gonio.brdf import models

    seeds = []
    rgb = models.Lambert(albedo=[0.5, 0.35, 0.2]) + models.TorranceSparrow(alpha=0.3, rho_d=0.0)
    for name, model in (("lambert_ts", rgb), ("lambert_grey", models.Lambert(albedo=0.6))):
        p = out / f"{name}.bsdf"
        io.save(model, p)
        seeds.append(Seed(f"rgl:written-{name}", "rgl", p))
    return seeds


def build_corpus(out: Path, real: bool = True) -> list[Seed]:
    """Write the generated corpus into ``out`` and return it with the available real files."""
    from gonio import io
    from gonio.io.exr import write_exr, write_table_slices
    from gonio.io.native import write_native

    out.mkdir(parents=True, exist_ok=True)
    seeds: list[Seed] = []
    with _fixed_time():
        small = _half_diff_table((6, 6, 12), 1)
        p = out / "gridded.brdf.h5"
        write_native(small, p)
        seeds.append(Seed("native:gridded", "native", p))
        # big enough for chunked, compressed datasets (shuffle + deflate)
        p = out / "gridded_chunked.brdf.h5"
        write_native(_half_diff_table((16, 16, 32), 2), p)
        seeds.append(Seed("native:gridded-chunked", "native", p))
        p = out / "gridded_lossy.brdf.h5"
        write_native(_half_diff_table((16, 16, 32), 3), p, lossy=0.01)
        seeds.append(Seed("native:gridded-lossy", "native", p))
        p = out / "scattered.brdf.h5"
        write_native(_samples(200, 4), p)
        seeds.append(Seed("native:scattered", "native", p))
        p = out / "scattered_chunked.brdf.h5"
        write_native(_samples(1500, 5, n_ch=1), p)
        seeds.append(Seed("native:scattered-chunked", "native", p))
        p = out / "run_table.brdf.h5"  # a run's layout: samples at the root, a gridded group
        write_native(_samples(100, 6), p, groups={"gridded": small})
        seeds.append(Seed("native:run-groups", "native", p))
    for name in ("tiny-gridded.brdf.h5", "tiny-scattered.brdf.h5"):
        seeds.append(Seed(f"native:example-{name}", "native", EXAMPLES / name))
    p = out / "small.binary"  # MERL at a reduced resolution (the reader takes any dimensions)
    io.save(_half_diff_table((5, 5, 10), 8), p)
    seeds.append(Seed("merl:5x5x10", "merl", p))
    p = out / "small.brdf"
    p.write_text(_cornell_text(40, 9))
    seeds.append(Seed("cornell:generated", "cornell", p))
    p = out / "small.alta"
    p.write_text(_alta_text(40, 10))
    seeds.append(Seed("alta:generated-vs2", "alta", p))
    p = out / "image.exr"
    write_exr(p, np.random.default_rng(11).random((8, 12, 3)).astype(np.float32))
    seeds.append(Seed("exr:image", "exr", p))
    p = out / "slices.exr"
    write_table_slices(_half_diff_table((6, 6, 4), 12), p)
    seeds.append(Seed("exr:table-slices", "exr_slices", p))
    rigs = Path(__import__("gonio.rigs", fromlist=["x"]).__file__).parent
    for name in SHIPPED_RIGS:
        seeds.append(Seed(f"rig:{name}", "rig", rigs / name))
    seeds += _plans(out)
    seeds += _fit_json(out)
    with _fixed_time():
        seeds += _prior_files(out)
    seeds += _rgl_written(out)
    if has_nbrdf_reader():
        from tests.fuzz.nbrdf import seed_archives

        seeds += [Seed(f"nbrdf:{n}", "nbrdf", p) for n, p in seed_archives(out, real)]
    if real:
        for kind, files in REAL_FILES.items():
            for rel in files:
                path = SHARED_DATA / rel
                if path.is_file():
                    seeds.append(Seed(f"real:{rel}", kind, path))
    return seeds
