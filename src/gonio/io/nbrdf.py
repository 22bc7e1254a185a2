"""Neural BRDFs (Sztrajman et al. 2021): small Keras MLPs fitted to MERL materials, read from a zip.

An archive such as ``merl_nbrdf.zip`` (the Neural-BRDF repository's ``data/merl_nbrdf.zip``)
holds, per material ``NAME``, ``.../NAME.json`` (the Keras ``Sequential`` model description) and
``.../NAME.h5`` (its weights). Address one material as ``"ARCHIVE.zip::NAME"``:

>>> from gonio import io
>>> table = io.load("merl_nbrdf.zip::gold-paint")     # MERL-grid TabulatedBRDF, RGB, 1/sr
>>> net = read_nbrdf("merl_nbrdf.zip", "gold-paint")  # the network itself: net.f(wi, wo)

Nothing in the archive is executed: the zip is read with :mod:`zipfile`, the model description
with :mod:`json` and the weights with :mod:`h5py`. The description's final ``Lambda`` layer is
stored as marshalled Python bytecode; it is not run. Its meaning comes from the repository's
documentation (``shared/data/nbrdf/README.md``): ``f_r = expm1(dense output)``.

Conventions (from the repository's ``coords.py`` and its Mitsuba plugin):

* **Input**, per direction pair: six numbers ``[sin θh, 0, cos θh, sin θd cos φd, sin θd sin φd,
  cos θd]``: the half vector in the local frame with ``φh`` set to 0, followed by the
  Rusinkiewicz (1998) difference vector (``wi`` in the frame whose pole is the half vector, as in
  :func:`gonio.brdf.frames.half_diff`).
* **Layers**: ``Dense`` after ``Dense``, kernels stored ``(in, out)`` (``y = x @ K + b``), ReLU
  between layers, none after the last; evaluated in float32 as Keras does.
* **Output**: three numbers whose ``expm1`` is ``f_r`` in sr⁻¹ (RGB, no cosine factor) with
  MERL's channel scales ``(1, 1.15, 1.66) / 1500`` already applied.
* **Negative outputs**: ``expm1`` of a negative output is negative; 31 of the 88 published
  networks dip below 0 at valid cells of the MERL grid (from one cell to a fifth of them, by
  -1e-5 to -0.39 sr⁻¹ at the lowest; beige-fabric in 119 cells down to -0.097, pink-plastic in
  91 down to -0.39, 6 % of its peak). The authors' own decoder clamps them: their Mitsuba
  plugin's ``nn.h`` returns ``max(expm1(output), 0)`` and their PyTorch training code ends the
  network with the same ReLU, so the networks were trained and are rendered with those cells
  at 0. A network is a model of a measurement, not a measurement: gonio decodes it the same
  way by default
  (``negative="clamp"``) and records what it clamped in the table's provenance
  (``meta["source"]["clamped_cells"]``, ``["clamped_values"]``, ``["lowest_output"]``;
  ``gonio fit`` copies it into the fit JSON's ``data``). ``negative="keep"`` returns the raw
  output instead, and then a network clearly below 0 (beyond
  :data:`gonio.io._sanity.NEGATIVE_TOLERANCE` of its peak) is refused in one line as any reader
  refuses clearly negative values. Either way a network whose output is non-finite, beyond
  1e10 sr⁻¹ or nowhere positive is refused (corruption, not a material).
* **MERL grid**: the networks were trained with MERL cell ``i`` placed at the cell's start,
  ``θh = (i/90)² π/2``, ``θd = i/90 · π/2``, ``φd = i/180 · π`` (``merl_axes(cells="start")``);
  :meth:`NBRDF.to_table` evaluates there and stores the values on MERL's own nodes
  (:func:`gonio.io.merl.merl_axes`, cell centres), so the result is read like the MERL
  ``.binary`` the network stands for (cells with a direction at or below the horizon are
  invalid).
"""

from __future__ import annotations

import itertools
import os
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gonio._bounded import loads_json
from gonio.errors import FormatError
from gonio.io._common import PathLike, check_input_file, fail
from gonio.io._hdf5_guard import (
    check_global_heaps,
    check_group_datasets,
    close_bounded,
    open_bounded,
)
from gonio.io._sanity import check_brdf_values
from gonio.io.merl import MERL_DIMS, merl_axes

if TYPE_CHECKING:
    from gonio.brdf.tabulated import TabulatedBRDF

#: Separator between the archive path and the material name in ``io.load`` paths.
MEMBER_SEP = "::"
#: Bounds on a network's architecture, checked on its description before any weight is read
#: or any activation allocated. The published networks are 6 -> 21 -> 21 -> 3 (3 Dense layers,
#: 630 multiply-adds per query); a network may have up to 8 Dense layers of up to 256 units and
#: 16,384 multiply-adds per query (26 times theirs), so that tabulating MERL's grid takes seconds
#: and :data:`CHUNK_ROWS` rows of activations at most 64 MiB per layer.
MAX_DENSE_LAYERS = 8
MAX_UNITS = 256
MAX_MULTIPLY_ADDS = 1 << 14
#: Rows a tabulation evaluates at once (the activations of one chunk: rows x units x 4 bytes).
CHUNK_ROWS = 1 << 16
#: Largest member read from an archive (a real network's files are under 20 kB): bounds what a
#: highly compressible member can make the reader allocate.
MAX_MEMBER_BYTES = 16 << 20
#: What reading a corrupted member raises (bad deflate data, an unknown or encrypted method).
_ZIP_ERRORS = (zipfile.BadZipFile, OSError, KeyError, EOFError, zlib.error,
               NotImplementedError, RuntimeError, ValueError)  # fmt: skip
#: What :meth:`NBRDF.to_table` does with negative network outputs (module docstring).
NEGATIVE_POLICIES = ("clamp", "keep")
_JIT_FORWARD: Any = None
#: Grid on which :meth:`NBRDFArchive.read` probes a network (as :meth:`NBRDF.to_table`).
_PROBE_DIMS = (16, 16, 32)


def split_member(path: PathLike) -> tuple[str, str] | None:
    """``(archive, name)`` for a path of the form ``"ARCHIVE.zip::NAME"``, else None."""
    text = os.fspath(path)
    if MEMBER_SEP not in text:
        return None
    archive, _, name = text.rpartition(MEMBER_SEP)
    return archive, name


@dataclass(frozen=True)
class NBRDF:
    """One neural BRDF: a ReLU MLP from the six input features to ``log1p(f_r)`` per channel.

    Attributes
    ----------
    name : material name.
    kernels : per layer a float32 ``(n_in, n_out)`` kernel; the first takes 6 inputs, the last
        gives 3 outputs.
    biases : per layer a float32 ``(n_out,)`` bias.
    source : archive path and member names, for provenance.
    """

    name: str
    kernels: tuple[np.ndarray, ...]
    biases: tuple[np.ndarray, ...]
    source: dict[str, Any] = field(default_factory=dict)

    @staticmethod
    def features(wi: Any, wo: Any) -> np.ndarray:
        """The network input ``(..., 6)`` float32 for direction pairs ``(..., 3)`` each.

        ``[sin θh, 0, cos θh, d_x, d_y, d_z]`` with ``d`` the difference vector (unit).
        """
        wi = np.asarray(wi, dtype=np.float64)
        wo = np.asarray(wo, dtype=np.float64)
        wi, wo = np.broadcast_arrays(wi, wo)
        h = wi + wo
        h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
        cos_h = np.clip(h[..., 2], -1.0, 1.0)
        sin_h = np.sqrt(np.maximum(1.0 - cos_h * cos_h, 0.0))
        phi_h = np.arctan2(h[..., 1], h[..., 0])
        cp, sp = np.cos(phi_h), np.sin(phi_h)
        # wi rotated by -phi_h about z, then by -theta_h about y
        x = cp * wi[..., 0] + sp * wi[..., 1]
        y = -sp * wi[..., 0] + cp * wi[..., 1]
        z = wi[..., 2]
        dx = cos_h * x - sin_h * z
        dz = sin_h * x + cos_h * z
        out = np.stack([sin_h, np.zeros_like(sin_h), cos_h, dx, y, dz], axis=-1)
        return out.astype(np.float32)

    def forward(self, x: np.ndarray) -> np.ndarray:
        """Dense layers on the features ``x`` ``(..., 6)`` -> ``(..., 3)`` (float32 ``log1p f``)."""
        a = np.asarray(x, dtype=np.float32)
        shape = a.shape[:-1]
        a = a.reshape(-1, a.shape[-1])
        last = len(self.kernels) - 1
        for i, (k, b) in enumerate(zip(self.kernels, self.biases, strict=True)):
            a = a @ k + b
            if i < last:
                np.maximum(a, 0.0, out=a)
        return a.reshape(*shape, a.shape[-1])

    def _forward_many(self, x: np.ndarray) -> np.ndarray:
        """:meth:`forward` of many rows ``(N, 6)`` float32, :data:`CHUNK_ROWS` at a time (memory
        bounded whatever ``N``). Each chunk runs as one compiled XLA program (the layers fused,
        about three times NumPy's speed on a MERL grid) whose weights are arguments; the last
        chunk is padded to the same length, so that every network of the same architecture
        shares one program (and the persistent compilation cache, :mod:`gonio.compile_cache`).
        Fewer rows than one chunk go through :meth:`forward` (no compilation)."""
        n = x.shape[0]
        if n < CHUNK_ROWS:
            return self.forward(x)
        import jax
        import jax.numpy as jnp

        global _JIT_FORWARD
        if _JIT_FORWARD is None:

            def dense(x: Any, kernels: Any, biases: Any) -> Any:
                a = x
                for i, (k, b) in enumerate(zip(kernels, biases, strict=True)):
                    a = a @ k + b
                    if i < len(kernels) - 1:
                        a = jnp.maximum(a, 0.0)
                return a

            _JIT_FORWARD = jax.jit(dense)
        out = np.empty((n, self.kernels[-1].shape[1]), dtype=np.float32)
        for s in range(0, n, CHUNK_ROWS):
            rows = x[s : s + CHUNK_ROWS]
            m = rows.shape[0]
            if m < CHUNK_ROWS:
                rows = np.concatenate([rows, np.zeros((CHUNK_ROWS - m, x.shape[1]), x.dtype)])
            y = _JIT_FORWARD(jnp.asarray(rows), self.kernels, self.biases)
            out[s : s + m] = np.asarray(y, dtype=np.float32)[:m]
        return out

    def f(self, wi: Any, wo: Any, chunk: int = 1 << 18, negative: str = "clamp") -> np.ndarray:
        """``f_r(wi, wo)`` in sr⁻¹, ``(..., 3)`` float64, for unit directions in the local frame.

        Pairs with a direction at or below the horizon give 0 (gonio's convention for every BRDF);
        negative outputs are clamped at 0 as the authors' decoder does, unless ``negative`` is
        ``"keep"`` (module docstring). An output that is not finite or beyond ``MAX_BRDF`` at
        any pair above the horizon is a FormatError naming the archive, as in :meth:`to_table`.
        """
        if negative not in NEGATIVE_POLICIES:
            raise ValueError(f"negative must be one of {NEGATIVE_POLICIES}, not {negative!r}")
        wi = np.asarray(wi, dtype=np.float64)
        wo = np.asarray(wo, dtype=np.float64)
        wi, wo = np.broadcast_arrays(wi, wo)
        shape = wi.shape[:-1]
        wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
        out = np.empty((wi.shape[0], 3), dtype=np.float64)
        for s in range(0, wi.shape[0], chunk):
            sl = slice(s, s + chunk)
            with np.errstate(over="ignore", invalid="ignore"):  # non-finite: refused below
                out[sl] = np.expm1(self.forward(self.features(wi[sl], wo[sl])))
        ok = (wi[:, 2] > 0) & (wo[:, 2] > 0)
        out[~ok] = 0.0
        if np.any(ok):  # what the network gives, not only what its table stores, is checked
            where = self.source.get("archive", self.name)
            check_brdf_values(where, f"{self.name}: network output", out[ok], non_negative=False)
        if negative == "clamp":
            np.maximum(out, 0.0, out=out)
        return out.reshape(*shape, 3)

    def to_table(
        self, dims: tuple[int, int, int] = MERL_DIMS, negative: str = "clamp"
    ) -> TabulatedBRDF:
        """The network on the nodes of a MERL-like ``(θh, θd, φd)`` grid, as a ``half_diff_iso``
        :class:`~gonio.brdf.tabulated.TabulatedBRDF` (RGB, sr⁻¹, nearest-cell lookup like a MERL
        file); cells with a direction at or below the horizon are invalid.

        Parameters
        ----------
        dims : cells along ``(θh, θd, φd)``.
        negative : {"clamp", "keep"}
            ``"clamp"`` (default, the authors' decoder): negative outputs become 0 and their
            count goes into ``meta["source"]``; ``"keep"``: the raw output, refused when
            clearly negative (see the module docstring).
        """
        if negative not in NEGATIVE_POLICIES:
            raise ValueError(f"negative must be one of {NEGATIVE_POLICIES}, not {negative!r}")
        from gonio.brdf.tabulated import Channels, TabulatedBRDF

        # the network was trained with MERL cell i at the cell's start: its value for cell i is
        # the network there; the table's nodes are MERL's (cell centres, gonio.io.merl), so it
        # is looked up like the MERL file the network stands for
        axes = merl_axes(dims)
        th, td, pd = (
            np.asarray(a.nodes(), dtype=np.float64) for a in merl_axes(dims, cells="start")
        )
        # per axis, broadcast against the others (the same numbers as on a meshgrid, with the
        # sines and cosines of 360 values instead of 1.5e6 each)
        th, td, pd = th[:, None, None], td[None, :, None], pd[None, None, :]
        # directions of the nodes (phi_h = 0), as in gonio.brdf.frames.half_diff_to_directions:
        # d is the difference vector, wi = R_y(theta_h) d and wo = R_y(theta_h) (-d_x, -d_y, d_z),
        # so their z components are cos(theta_h) d_z -/+ sin(theta_h) d_x
        st = np.sin(td)
        dx, dy, dz = st * np.cos(pd), st * np.sin(pd), np.cos(td)
        sh, ch = np.sin(th), np.cos(th)
        mask = (ch * dz - sh * dx > 0) & (ch * dz + sh * dx > 0)
        # the features of a node are known in closed form; only valid cells are evaluated
        feats = np.zeros((int(mask.sum()), 6), dtype=np.float32)
        for col, v in ((0, sh), (2, ch), (3, dx), (4, dy), (5, dz)):
            feats[:, col] = np.broadcast_to(v, mask.shape)[mask]
        vals = np.zeros((*mask.shape, 3), dtype=np.float32)
        with np.errstate(over="ignore", invalid="ignore"):  # non-finite output: refused below
            vals[mask] = np.expm1(self._forward_many(feats))
        where = self.source.get("archive", self.name)
        what = f"{self.name}: network output"
        check_brdf_values(where, what, vals, mask, non_negative=negative == "keep")
        source: dict[str, Any] = {"format": "nbrdf", **self.source, "negative": negative}
        if negative == "clamp":
            below = vals < 0  # only valid cells: the others are 0 already
            source["clamped_values"] = int(np.count_nonzero(below))
            source["clamped_cells"] = int(np.count_nonzero(below.any(axis=-1)))
            source["lowest_output"] = float(min(vals.min(), 0.0))
            np.maximum(vals, 0.0, out=vals)
        if not np.any(vals[mask] > 0):
            raise fail(where, f"{what}: nowhere positive at valid cells")
        return TabulatedBRDF(
            values=vals,
            axes=axes,
            parameterization="half_diff_iso",
            mask=mask,
            channels=Channels.rgb(),
            meta={"name": self.name, "source": source},
            interpolation="nearest",
        )


class NBRDFArchive:
    """A zip of neural BRDFs; see the module docstring.

    Parameters
    ----------
    path : the ``.zip`` file.

    Raises
    ------
    FormatError
        Missing or unreadable file, not a zip archive, or no material in it.
    """

    def __init__(self, path: PathLike) -> None:
        self.path = check_input_file(path)
        try:
            with zipfile.ZipFile(self.path) as zf:
                members = zf.namelist()
        except _ZIP_ERRORS as exc:
            raise fail(self.path, f"not a readable zip archive ({exc})") from None
        found: dict[str, dict[str, str]] = {}
        for m in members:
            base = m.rsplit("/", 1)[-1]
            stem, dot, ext = base.rpartition(".")
            if dot and ext in ("json", "h5") and stem:
                found.setdefault(stem, {})[ext] = m
        self._members = found
        self.names = sorted(k for k, v in found.items() if len(v) == 2)
        if not self.names:
            raise fail(self.path, "no neural BRDF (NAME.json + NAME.h5) in this zip archive")

    def read(self, name: str) -> NBRDF:
        """The network of material ``name``; FormatError (one line) when absent or malformed."""
        entry = self._members.get(name)
        if entry is None or len(entry) != 2:
            near = [n for n in self.names if name.lower() in n.lower()][:5]
            hint = (
                f"; similar: {', '.join(near)}" if near else f"; e.g. {', '.join(self.names[:3])}"
            )
            what = "lacks its .json or .h5 file" if entry else "is not in the archive"
            raise fail(self.path, f"material {name!r} {what} ({len(self.names)} materials{hint})")
        try:
            with zipfile.ZipFile(self.path) as zf:
                desc = _read_member(zf, entry["json"], self.path)
                weights = _read_member(zf, entry["h5"], self.path)
        except FormatError:
            raise
        except _ZIP_ERRORS as exc:
            raise fail(self.path, f"{name}: cannot read its members ({exc})") from None
        units = _parse_description(desc, self.path, name)
        kernels, biases = _read_weights(weights, units, self.path, name)
        net = NBRDF(
            name,
            kernels,
            biases,
            {"archive": str(self.path), "json": entry["json"], "h5": entry["h5"]},
        )
        _probe(net, self.path)
        return net


def _read_member(zf: zipfile.ZipFile, member: str, path: Path) -> bytes:
    """A member's bytes, refusing more than :data:`MAX_MEMBER_BYTES` (declared or actual)."""
    info = zf.getinfo(member)
    if info.file_size > MAX_MEMBER_BYTES:
        raise fail(path, f"member {member} declares {info.file_size} bytes (at most "
                         f"{MAX_MEMBER_BYTES})")  # fmt: skip
    with zf.open(info) as fh:
        data = fh.read(MAX_MEMBER_BYTES + 1)
    if len(data) > MAX_MEMBER_BYTES:
        raise fail(path, f"member {member} holds more than {MAX_MEMBER_BYTES} bytes")
    return data


#: Largest weight magnitude accepted (the published networks reach 11.1).
MAX_WEIGHT = 1e3


def _probe(net: NBRDF, path: Path) -> None:
    """Refuse a network whose output on a MERL-like grid is non-finite, beyond 1e10 1/sr or
    nowhere positive (finite weights can still overflow float32: corruption, not a material)."""
    net.to_table(_PROBE_DIMS)  # checks its values (NBRDF.to_table)


def _parse_description(text: bytes, path: Path, name: str) -> list[tuple[str, int]]:
    """``[(layer name, units)]`` of the Dense layers; checks the architecture is the known one."""
    where = f"{name}.json"
    try:
        desc = loads_json(text, where)  # size, UTF-8 and nesting bounds
    except FormatError as exc:
        raise fail(path, f"not a Keras model description ({exc})") from None
    try:
        if not isinstance(desc, dict):
            raise TypeError("not a JSON object")
        layers = desc["config"]["layers"] if isinstance(desc["config"], dict) else desc["config"]
        if desc.get("class_name") != "Sequential" or not isinstance(layers, list):
            raise ValueError("not a Keras Sequential model")
    except (ValueError, KeyError, TypeError) as exc:
        raise fail(path, f"{where}: not a Keras model description ({exc})") from None
    dense: list[tuple[str, int]] = []
    for i, layer in enumerate(layers):
        cls = layer.get("class_name") if isinstance(layer, dict) else None
        cfg = layer.get("config", {}) if isinstance(layer, dict) else {}
        if not isinstance(cfg, dict):
            raise fail(path, f"{where}: layer {i} config is not an object")
        if cls == "Dense":
            units = cfg.get("units")
            if type(units) is not int or not 0 < units <= MAX_UNITS:
                raise fail(
                    path, f"{where}: layer {i} has impossible units {units!r} (at most {MAX_UNITS})"
                )
            act = cfg.get("activation")
            dense.append((str(cfg.get("name")), units))
            if act not in ("relu", "linear"):
                raise fail(path, f"{where}: layer {i} has unsupported activation {act!r}")
        elif cls == "Lambda" and i == len(layers) - 1:
            continue  # expm1 of the output (not executed; see the module docstring)
        else:
            raise fail(path, f"{where}: unsupported layer {cls!r} at position {i}")
    if not dense or dense[-1][1] != 3:
        raise fail(path, f"{where}: expected Dense layers ending in 3 outputs")
    _check_architecture(dense, path, where)
    return dense


def _check_architecture(dense: list[tuple[str, int]], path: Path, where: str) -> None:
    """Refuse a network beyond :data:`MAX_DENSE_LAYERS` or :data:`MAX_MULTIPLY_ADDS` (the
    cost of tabulating it), before its weights are read."""
    if len(dense) > MAX_DENSE_LAYERS:
        raise fail(path, f"{where}: {len(dense)} Dense layers (at most {MAX_DENSE_LAYERS})")
    sizes = [6, *(u for _, u in dense)]
    macs = sum(a * b for a, b in itertools.pairwise(sizes))
    if macs > MAX_MULTIPLY_ADDS:
        shape = " -> ".join(map(str, sizes))
        raise fail(
            path,
            f"{where}: network {shape} needs {macs} multiply-adds per query (at most "
            f"{MAX_MULTIPLY_ADDS}; the published networks need 630)",
        )


def _read_weights(
    data: bytes, units: list[tuple[str, int]], path: Path, name: str
) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
    """The kernels and biases of the Dense layers ``units``, read through the bounded HDF5
    path of native files (:mod:`gonio.io._hdf5_guard`): the storage of every dataset and every
    global heap are checked before libhdf5 decodes them, and reads are budgeted."""
    where = f"{name}.h5"
    kernels, biases = [], []
    try:
        h5 = open_bounded(data)
        try:
            raw = check_group_datasets(h5, path, len(data))
            check_global_heaps(path, raw, data)
            root = h5["model_weights"] if "model_weights" in h5 else h5
            n_in = 6
            for layer, n_out in units:
                k, b = _layer_weights(root, layer, (n_in, n_out), path, where)
                kernels.append(k)
                biases.append(b)
                n_in = n_out
        finally:
            close_bounded(h5)
    except FormatError:
        raise
    except (OSError, KeyError, ValueError, TypeError, RuntimeError) as exc:
        raise fail(path, f"{where}: not a readable Keras weights file ({exc})") from None
    return tuple(kernels), tuple(biases)


def _layer_weights(
    root: Any, layer: str, shape: tuple[int, int], path: Path, where: str
) -> tuple[np.ndarray, np.ndarray]:
    """Kernel ``shape`` ``(n_in, n_out)`` and bias ``(n_out,)`` float32 of one Dense layer,
    checked (shapes before reading, finite, within :data:`MAX_WEIGHT`)."""
    import h5py

    n_in, n_out = shape
    if layer not in root:
        raise fail(path, f"{where}: no weights for layer {layer!r}")
    group = root[layer]
    k = b = None
    for wname in group.attrs.get("weight_names", []):
        wname = wname.decode() if isinstance(wname, bytes) else str(wname)
        ds = group[wname] if wname in group else group[wname.split("/", 1)[-1]]
        want = (n_in, n_out) if wname.endswith("kernel:0") else (n_out,)
        if not isinstance(ds, h5py.Dataset) or ds.shape != want:
            shape_ = getattr(ds, "shape", None)
            raise fail(path, f"{where}: {wname} has shape {shape_}, expected {want}")
        if wname.endswith("kernel:0"):
            k = np.asarray(ds, dtype=np.float32)
        elif wname.endswith("bias:0"):
            b = np.asarray(ds, dtype=np.float32)
    if k is None or b is None:
        raise fail(path, f"{where}: layer {layer!r} lacks its kernel or bias")
    if k.shape != (n_in, n_out) or b.shape != (n_out,):
        raise fail(
            path,
            f"{where}: layer {layer!r} has kernel {k.shape} and bias {b.shape}, "
            f"expected ({n_in}, {n_out}) and ({n_out},)",
        )
    if not (np.all(np.isfinite(k)) and np.all(np.isfinite(b))):
        raise fail(path, f"{where}: non-finite weights in layer {layer!r}")
    # the 88 published networks stay below 12 in magnitude; weights far beyond that overflow
    # float32 away from the probe grid: corruption, not a material
    if max(np.abs(k).max(initial=0.0), np.abs(b).max(initial=0.0)) > MAX_WEIGHT:
        raise fail(path, f"{where}: layer {layer!r} has weights beyond {MAX_WEIGHT:g}")
    return k, b


def read_nbrdf(path: PathLike, name: str | None = None) -> NBRDF:
    """The network of one material: ``read_nbrdf("merl_nbrdf.zip", "gold-paint")`` or
    ``read_nbrdf("merl_nbrdf.zip::gold-paint")``."""
    if name is None:
        parts = split_member(path)
        if parts is None:
            names = NBRDFArchive(path).names
            raise fail(
                path,
                f"name one of its {len(names)} materials as ARCHIVE.zip{MEMBER_SEP}NAME "
                f"(e.g. {', '.join(names[:3])})",
            )
        path, name = parts
    if not name:
        raise fail(path, f"empty material name after {MEMBER_SEP!r}")
    return NBRDFArchive(path).read(name)


def load_nbrdf_table(path: PathLike, negative: str = "clamp") -> TabulatedBRDF:
    """``io.load`` of ``"ARCHIVE.zip::NAME"``: the network tabulated on MERL's grid
    (``negative``: see :meth:`NBRDF.to_table`)."""
    if negative not in NEGATIVE_POLICIES:
        raise ValueError(f"negative must be one of {NEGATIVE_POLICIES}, not {negative!r}")
    return read_nbrdf(path).to_table(negative=negative)


def list_materials(path: PathLike) -> list[str]:
    """Names of the materials in an archive (both files present), sorted."""
    return list(NBRDFArchive(path).names)
