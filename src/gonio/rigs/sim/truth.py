"""The simulated sample's ground truth: an analytic gonio model or a measured table from a file.

A rig file's ``[sim.sample]`` is either a model description (``Node.to_dict()`` form)::

    [sim.sample]
    type = "Phong"
    params = { rho_d = [0.3, 0.25, 0.2], rho_s = 0.4, n = 80.0 }

or a tabulated BRDF read through :func:`gonio.io.load` (RGL ``.bsdf``, MERL ``.binary``, native
``.brdf.h5``), so that a real material's measurement is what the simulated rig sees::

    [sim.sample]
    file = "../shared/data/rgl/vch_golden_yellow_rgb.bsdf"   # relative to the rig file

or a member of a neural-BRDF archive, addressed as :func:`gonio.io.load` does
(``ARCHIVE.zip::NAME``; the archive relative to the rig file), so that any material of a shared
archive can be the truth without writing a table::

    [sim.sample]
    file = "../shared/data/nbrdf/merl_nbrdf.zip::gold-paint"

Measured RGB tables can hold small negative values where a spectral measurement was converted to
RGB; a reflectance cannot be negative, so the ground truth clamps them to zero.

An RGL file is tabulated with its reciprocal part, ``(f(wi, wo) + f(wo, wi)) / 2``
(:meth:`gonio.io.rgl_measured.RGLMeasured.to_table` with ``reciprocal=True``). Taken from one half
of ``phi_d`` only, the folded table of a not-quite-reciprocal measurement has a one-cell ramp on the
plane of incidence (~5 % of f within 1 degree of ``phi_d`` for the acrylic felt), far sharper than
any real surface: the measured spot (a few tenths of a degree wide) straddles it at every in-plane
geometry, which biased the simulated measurements by up to ~3 sigma against the truth at the
spot centre.

Known limit: some RGL files (``vch_golden_yellow``, ``cc_ibiza_sunset``) are singular where the
light is at the normal: the evaluator conditions on ``wi``'s azimuth, and ``f`` with ``wi`` 0.1
degree off the normal differs by up to 2.4x between offset azimuths. The reciprocal average takes
that branch in, so simulated measurements with the light within a spot's width of the normal
(``theta_i = 0``) disagree with the truth at the spot centre by many sigma on those files.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Any

from gonio.errors import FormatError, RigConfigError


def truth_file(spec: dict, source: str) -> Path | None:
    """The table file named by a ``[sim.sample]`` spec (relative to the rig file), or None.

    Raises
    ------
    ValueError
        When the spec mixes ``file`` with model keys (the message names the key).
    """
    if "file" not in spec:
        return None
    extra = sorted(set(spec) - {"file"})
    if extra:
        raise ValueError(f"{extra[0]}: not allowed beside 'file'")
    from gonio.io.nbrdf import MEMBER_SEP, split_member

    text = str(spec["file"])
    parts = split_member(text)
    p = Path(parts[0] if parts else text).expanduser()
    src = Path(source)
    if not p.is_absolute() and src.suffix == ".toml" and src.parent.is_dir():
        p = src.parent / p
    return Path(f"{p}{MEMBER_SEP}{parts[1]}") if parts else p


def file_part(path: Path) -> Path:
    """The file on disk of a :func:`truth_file` path: the archive of ``ARCHIVE::NAME``."""
    from gonio.io.nbrdf import split_member

    parts = split_member(path)
    return Path(parts[0]) if parts else path


class ClampedTable:
    """A tabulated BRDF whose ``f`` is clamped at zero (see the module docstring).

    Only ``f`` is offered: the simulated camera evaluates the ground truth, it never samples it.
    """

    def __init__(self, table: Any) -> None:
        self.table = table
        self.n_channels = table.n_channels

    def f(self, wi: Any, wo: Any) -> Any:
        import jax.numpy as jnp

        return jnp.maximum(self.table.f(wi, wo), 0.0)


@lru_cache(maxsize=4)
def _load_table(path: str, mtime_ns: int) -> ClampedTable:
    from gonio import io
    from gonio.io.detect import detect_format

    if detect_format(path) == "rgl":
        from gonio.io.rgl_measured import load_rgl

        obj = load_rgl(path).to_table(reciprocal=True)
    else:
        obj = io.load(path)
    from gonio.brdf.tabulated import TabulatedBRDF

    if not isinstance(obj, TabulatedBRDF):
        raise FormatError(
            f"{path}: holds scattered samples; a simulated sample needs a tabulated BRDF"
        )
    return ClampedTable(obj)


def load_truth(spec: dict, source: str) -> Any:
    """The ground truth of a ``[sim.sample]`` spec: a gonio model or a :class:`ClampedTable`.

    Raises
    ------
    RigConfigError
        When the file is missing or the model description is invalid.
    FormatError
        When the file cannot be read as a tabulated BRDF.
    """
    try:
        path = truth_file(spec, source)
    except ValueError as exc:
        raise RigConfigError(f"{source}: sim.sample.{exc}") from None
    if path is None:
        from gonio.brdf.models import BRDFModel, Node

        try:
            model = Node.from_dict(spec)
        except Exception as exc:
            raise RigConfigError(f"{source}: sim.sample: not a gonio model: {exc}") from None
        if not isinstance(model, BRDFModel):
            raise RigConfigError(
                f"{source}: sim.sample: {type(model).__name__} is not a BRDF model"
            )
        return model
    disk = file_part(path)
    if not disk.is_file():
        raise RigConfigError(f"{source}: sim.sample.file: no such file: {disk}")
    member = str(path)[len(str(disk)) :]  # "::NAME" of an archive member, else ""
    return _load_table(str(disk.resolve()) + member, disk.stat().st_mtime_ns)
