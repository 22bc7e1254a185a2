"""Any table gonio reads, made renderable: gridded, with full coverage, in RGB or grey.

The sphere renderer needs a material it can evaluate and importance-sample everywhere on the
hemisphere. Measured data comes in shapes it cannot use directly; :func:`renderable` adapts each:

* **Scattered samples** (``gonio acquire``'s ``RUN/table.brdf.h5``, ALTA, Cornell): tabulated on
  a 64 x 32 x 32 isotropic half/diff grid (sqrt-warped theta_h) through the log-linear Delaunay
  interpolant (:meth:`gonio.brdf.measured.MeasuredSamples.interpolant`). Outside the samples' convex
  hull the nearest sample's value is used (extrapolation; the note says how much of the grid
  that is); samples that span only a line or a plane (a 1-D ``COS_TH`` ALTA file) are
  interpolated along it and extended off it. Its error on a simulated acquisition of a known
  material is measured by ``benchmarks/bench_scattered_render.py``.
* **Gridded tables with holes** (a binned table from ``gonio grid``, or a run's ``/gridded``):
  the valid nodes are treated as samples and interpolated the same way (onto the render grid
  when the table's own grid is coarser), so uncovered cells do not render black. Tables with
  every node above the horizon valid (MERL, RGL tabulations) are rendered as they are.
* **Spectral data** (Cornell's 31 wavelengths): converted to linear sRGB through CIE 1931 XYZ
  under the lights' spectrum. The renderer's lights are RGB; their white (1, 1, 1) is the white
  of sRGB, D65, so ``illuminant="D65"`` is the consistent choice (default): a spectrally flat
  BRDF of value c becomes RGB (c, c, c). Out-of-gamut colours are clipped at 0 per channel.

The functions return the material and one-line notes saying what was done, for the CLI to show.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gonio.io.spectral import spectral_to_rgb_matrix

#: Largest number of valid nodes of a holey gridded table that are re-interpolated (the
#: Delaunay tetrahedralization of more points takes longer than the render).
MAX_FILL_NODES = 200_000


def rgb_samples(obj: Any, illuminant: str) -> Any:
    """Scattered spectral samples -> linear sRGB samples (sigma propagated linearly)."""
    from gonio.brdf.measured import MeasuredSamples
    from gonio.brdf.tabulated import Channels

    m = spectral_to_rgb_matrix(obj.channels.wavelengths_nm, illuminant)
    vals = np.maximum(np.asarray(obj.values) @ m, 0.0)
    sig = None
    if obj.sigma is not None:
        sig = np.sqrt(np.asarray(obj.sigma) ** 2 @ m**2)
    meta = dict(obj.meta)
    meta["color"] = f"spectral -> linear sRGB under {illuminant} (CIE 1931 2 deg)"
    return MeasuredSamples(obj.wi, obj.wo, vals, sig, Channels.rgb(), obj.weights, meta)


def _rgb_table(obj: Any, illuminant: str) -> Any:
    from gonio.brdf.tabulated import Channels

    m = spectral_to_rgb_matrix(obj.channels.wavelengths_nm, illuminant)
    vals = np.maximum(np.asarray(obj.values, dtype=np.float64) @ m, 0.0).astype(np.float32)
    sig = None
    if obj.sigma is not None:
        sig = np.sqrt(np.asarray(obj.sigma, dtype=np.float64) ** 2 @ m**2).astype(np.float32)
    meta = dict(obj.meta)
    meta["color"] = f"spectral -> linear sRGB under {illuminant} (CIE 1931 2 deg)"
    return obj.replace(values=vals, sigma=sig, channels=Channels.rgb(), meta=meta)


def renderable(obj: Any, *, illuminant: str = "D65") -> tuple[Any, list[str]]:
    """``obj`` (anything :func:`gonio.io.load` returns) as a material the renderer accepts.

    Returns ``(material, notes)``; see the module docstring for what is done to which input.
    Objects that already evaluate and sample themselves (analytic models, exact evaluators)
    pass through unchanged.
    """
    from gonio.brdf.measured import MeasuredSamples
    from gonio.brdf.tabulated import TabulatedBRDF
    from gonio.errors import ParameterError

    notes: list[str] = []
    info = obj.channel_info
    if isinstance(obj, MeasuredSamples | TabulatedBRDF) and info.kind == "spectral":
        n = len(info)
        obj = rgb_samples(obj, illuminant) if isinstance(obj, MeasuredSamples) else obj
        if isinstance(obj, TabulatedBRDF):
            obj = _rgb_table(obj, illuminant)
        notes.append(f"spectral data ({n} wavelengths) shown as linear sRGB under {illuminant}")
    if isinstance(obj, MeasuredSamples):
        if len(obj) < 1:
            raise ParameterError("the file holds no samples to render")
        table, covered = obj.interpolant(), obj.interpolant_coverage()
        notes.append(
            f"{len(obj)} scattered samples tabulated by log-linear Delaunay interpolation on a "
            f"{'x'.join(str(s) for s in table.shape)} half/diff grid; {covered:.0%} of it inside "
            "the samples' hull, the rest extrapolated from the nearest samples"
        )
        return table, notes
    if isinstance(obj, TabulatedBRDF):
        from gonio.brdf.gridding import above_horizon, filled_interpolant, render_axes

        above = above_horizon(obj)
        missing = above & ~obj.mask
        if missing.any() and obj.parameterization == "half_diff_iso":
            n_valid = int((obj.mask & above).sum())
            if n_valid == 0:
                raise ParameterError("the table has no valid nodes to render")
            if n_valid <= MAX_FILL_NODES:
                fine = render_axes()
                coarse = int(np.prod(obj.shape)) < int(np.prod([a.size for a in fine]))
                table, _ = filled_interpolant(
                    MeasuredSamples.from_table(obj), fine if coarse else obj.axes
                )
                notes.append(
                    f"{int(missing.sum())} of {int(above.sum())} grid nodes without data filled "
                    "by log-linear Delaunay interpolation of the valid ones"
                )
                return table, notes
            notes.append(f"{int(missing.sum())} grid nodes without data render as 0")
        return obj, notes
    return obj, notes
