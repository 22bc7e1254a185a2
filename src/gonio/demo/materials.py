"""What the demo's simulated sample is made of: a real measurement when one is at hand.

The demo looks for the RGL-EPFL measurements that sit beside a gonio checkout
(``../shared/data/rgl``); the first one found becomes the simulated sample's ground truth, so the
simulated rig measures a real material. Without that folder it falls back to a built-in analytic
material (a Lambertian base under a Torrance-Sparrow coat) whose parameters are known exactly,
which is also what the end-to-end test checks the recovered fit against.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gonio.errors import ParameterError

#: Environment variable naming the folder of third-party data (holding ``rgl/``).
DATA_ENV = "GONIO_DATA"

#: RGL-EPFL measurement files tried in order. Acrylic felt first: no
#: channel of it is near zero anywhere, so a weighted least-squares fit is well posed on all
#: three channels; the vinyl films have sharp highlights and blue values clamped at zero.
RGL_CANDIDATES: tuple[str, ...] = (
    "acrylic_felt_green_rgb.bsdf",
    "paper_white_rgb.bsdf",
    "vch_golden_yellow_rgb.bsdf",
    "cc_ibiza_sunset_rgb.bsdf",
)


@dataclass(frozen=True)
class DemoMaterial:
    """The simulated sample of a demo run.

    Attributes
    ----------
    name : short name used in titles and file names.
    description : one line for the report.
    sample : the rig file's ``[sim.sample]`` table (a model description or ``{"file": path}``).
    table_path : the measured table when the ground truth is a file, else None.
    truth_params : exact parameters of the matching fit preset when the ground truth is analytic
        (``{preset: {key: value}}``), else empty.
    """

    name: str
    description: str
    sample: dict
    table_path: Path | None = None
    truth_params: dict[str, dict[str, Any]] = field(default_factory=dict)

    @property
    def is_measured(self) -> bool:
        return self.table_path is not None


def builtin_material() -> DemoMaterial:
    """An orange glossy paint: Lambert albedo under a Beckmann Torrance-Sparrow coat.

    It is exactly the fit preset ``lambert+ts`` (Beckmann D, V-cavity G, Schlick Fresnel), so a
    fit of that preset must recover these parameters within its intervals.
    """
    from gonio.fit import presets

    model, _, _ = presets.build("lambert+ts")
    params = {
        "lambert.albedo": [0.55, 0.22, 0.06],
        "torrancesparrow.alpha": 0.18,
        "torrancesparrow.fresnel.f0": [0.05, 0.05, 0.05],
    }
    model = model.replace(**params)
    return DemoMaterial(
        name="builtin-orange-paint",
        description=(
            "built-in analytic material: Lambert albedo (0.55, 0.22, 0.06) under a Beckmann"
            " Torrance-Sparrow coat, alpha 0.18, Schlick f0 0.05"
        ),
        sample=model.to_dict(),
        truth_params={"lambert+ts": {**params, "torrancesparrow.rho_d": 0.0}},
    )


def data_folders() -> list[Path]:
    """Folders searched for third-party data, in order: ``$GONIO_DATA``, ``./../shared/data``,
    and ``shared/data`` beside the checkout this package was installed from."""
    out = []
    if os.environ.get(DATA_ENV):
        out.append(Path(os.environ[DATA_ENV]).expanduser())
    out.append(Path.cwd().parent / "shared" / "data")
    checkout = Path(__file__).resolve().parents[3]  # src/gonio/demo/materials.py -> checkout
    out.append(checkout.parent / "shared" / "data")
    return list(dict.fromkeys(out))


def table_material(path: Path) -> DemoMaterial:
    """A demo material whose ground truth is the tabulated BRDF in ``path``."""
    from gonio.rigs.sim.truth import load_truth

    path = Path(path).expanduser().resolve()
    if not path.is_file():
        raise ParameterError(f"--material: no such file: {path}")
    # read (and validate) the table now, before anything is created; the simulated camera gets
    # the same, cached, object
    table = load_truth({"file": str(path)}, "--material").table
    source = table.meta.get("source", {}) if isinstance(table.meta, dict) else {}
    text = source.get("description") if isinstance(source, dict) else None
    kind = "RGL-EPFL measurement" if path.suffix == ".bsdf" else "measured table"
    stem = path.name.split(".")[0].removesuffix("_rgb")
    return DemoMaterial(
        name=stem,
        description=f"{kind}: {text} ({path.name})" if text else f"{kind} {path.name}",
        sample={"file": str(path)},
        table_path=path,
    )


def find_material(choice: str = "auto") -> DemoMaterial:
    """The demo's material.

    Parameters
    ----------
    choice : ``"auto"`` (the first RGL file of :data:`RGL_CANDIDATES` found in
        :func:`data_folders`, else the built-in material), ``"builtin"``, or the path of any
        tabulated BRDF file gonio reads (RGL ``.bsdf``, MERL ``.binary``, ``.brdf.h5``).
    """
    if choice == "builtin":
        return builtin_material()
    if choice != "auto":
        return table_material(Path(choice))
    for folder in data_folders():
        for name in RGL_CANDIDATES:
            p = folder / "rgl" / name
            if p.is_file():
                return table_material(p)
    return builtin_material()
