"""The demo's export stage: every fitted model as a material for every renderer gonio.export
knows, written under ``export/`` with the mapping (exact or refit) and the refit's loss."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def export_fits(out: Path, models: list[Any], say: Any = None) -> None:
    """Export each model's fit (``m.files["fit"]``) to every target; records the rows in
    ``m.files["exports"]``: ``{target, mapping, family, files, metric, refit_data, refit_loss,
    original_loss}``."""
    from gonio.export import export, registry

    folder = out / "export"
    folder.mkdir(exist_ok=True)
    for m in models:
        fit_path = out / m.files["fit"]
        stem = fit_path.stem
        cache: dict[Any, Any] = {}
        rows = []
        for target, mod in registry.targets().items():
            if say is not None:
                say(f"{m.label} -> {target}")
            # unpriced: the losses only (the appearance part renders and scores each refit,
            # about a minute of CPU for the demo's fits; `gonio export` prices by default)
            e = export(fit_path, target, cache=cache, price=False)
            paths = e.write(folder / f"{stem}{mod.SUFFIXES[0]}")
            rows.append(
                {
                    "target": target,
                    "mapping": e.mapping,
                    "family": e.family,
                    "files": [p.relative_to(out).as_posix() for p in paths],
                    "metric": None if e.refit is None else e.refit["metric"],
                    "refit_data": None if e.refit is None else e.refit["data"]["kind"],
                    "refit_loss": None if e.refit is None else e.refit["refit_loss"],
                    "original_loss": None if e.refit is None else e.refit["original_loss"],
                }
            )
        m.files["exports"] = rows
