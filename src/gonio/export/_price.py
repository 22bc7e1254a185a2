"""The price of a refit: what the exported material costs against the fit and the measurement.

A refit (:mod:`._refit`) exports a material that is not the fit the report showed. Its price,
written to the terminal, the JSON report and a comment in the written file (:func:`comment`):

* the loss of the fit and of the refit on the same data under the fit's metric (from
  :func:`~gonio.export._refit.refit`);
* the appearance score (:mod:`gonio.appearance`: HDR-FLIP and relative L1 of exact point-light
  sphere images at 0, 30 and 60 degrees and of the studio image) of the fit and of the exported
  material against the measurement, when its file is readable, and the relative L1 of the
  exported material against the fit (with HDR-FLIP too when there is no measurement).

The measurement's images are rendered once per file and kept for the process
(:data:`_REFERENCES`), so a second export of the same fit only renders two models.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from gonio.brdf.models import BRDFModel

#: Measurement images by path (``gonio.appearance.SphereImages``), or why none.
_REFERENCES: dict[str, tuple[Any, str | None]] = {}
#: A fit's images and its score against the measurement, by (model description, path).
_FITS: dict[tuple[str, str | None], tuple[Any, dict[str, float] | None]] = {}


def _measurement_images(path: str) -> tuple[Any, str | None]:
    if path not in _REFERENCES:
        from gonio.fit.score import appearance_reference

        ref, why = appearance_reference(path)
        _REFERENCES[path] = (None if ref is None else ref.images, why)
    return _REFERENCES[path]


def _pick(s: dict[str, float]) -> dict[str, float]:
    return {k: float(s[k]) for k in ("hdr_flip", "rel_l1")}


class Pricer:
    """Prices exported models of one fit: the fit's and the measurement's images are rendered
    once (the measurement's once per process), the fit's score against the measurement once.

    Parameters
    ----------
    fit : the fitted model (1 or 3 channels).
    path : the measurement file the refit used, or None (a sampled model).
    """

    def __init__(self, fit: BRDFModel, path: str | None) -> None:
        from gonio.appearance import compare, render_images
        from gonio.io.strict_json import dumps_json

        self.path = path
        self.reference, why = (None, None) if path is None else _measurement_images(path)
        self.note: str | None = None
        if path is None:
            self.note = "no measurement file: the refit approximates the fitted model"
        elif self.reference is None:
            self.note = f"the measurement has no appearance images ({why})"
        key = (dumps_json(fit.to_dict()), path)
        if key not in _FITS:
            images = render_images(fit)
            score = None if self.reference is None else _pick(compare(self.reference, images))
            _FITS[key] = (images, score)
        self.fit_images, self.fit_score = _FITS[key]

    def price(self, exported: BRDFModel) -> dict[str, Any]:
        """The appearance part of a refit's price.

        Returns
        -------
        ``{"fit_vs_measurement": {hdr_flip, rel_l1} | None, "export_vs_measurement": ... |
        None, "export_vs_fit": {rel_l1, hdr_flip (only without a measurement)},
        "measurement": path | None, "note": str | None}``: means over the four images
        (0 = identical).
        """
        from gonio.appearance import IMAGES, compare, relative_l1, render_images

        im = render_images(exported)
        mask = self.fit_images.pixels.mask
        l1 = [relative_l1(self.fit_images.images[i], im.images[i], mask) for i in IMAGES]
        vs_fit: dict[str, float] = {"rel_l1": float(sum(l1) / len(l1))}
        vs_meas = None
        if self.reference is not None:
            vs_meas = _pick(compare(self.reference, im))
        else:  # the fit stands in for the measurement: its HDR-FLIP is the score
            vs_fit = _pick(compare(self.fit_images, im))
        return {
            "fit_vs_measurement": self.fit_score,
            "export_vs_measurement": vs_meas,
            "export_vs_fit": vs_fit,
            "measurement": self.path,
            "note": self.note,
        }


def _score(s: dict[str, float] | None) -> str:
    if s is None:
        return "n/a"
    flip = f"HDR-FLIP {s['hdr_flip']:.4f}, " if "hdr_flip" in s else ""
    return f"{flip}rel. L1 {s['rel_l1']:.4f}"


def lines(target: str, original: str, reason: str, r: dict[str, Any]) -> list[str]:
    """The price as text lines (terminal summary and file comment)."""
    d = r["data"]
    where = d["path"] if d["kind"] == "measurement" else "the fitted model, densely sampled"
    orig = r.get("original_loss_on_refit_data")
    orig_txt = "n/a" if orig is None else format(orig, ".6g")
    out = [
        f"REFIT, not the fit: {target} cannot express {original} ({reason}); "
        f"exported {r['family']} fitted to {d['n_samples']} samples of {where}",
        f"{r['metric']} loss on these samples: fit {orig_txt}, export {r['refit_loss']:.6g}",
    ]
    fm = r.get("on_refit_metric")
    if fm is not None and r.get("refit_metric") != r["metric"]:
        out.append(
            f"refitted under the {r['refit_metric']} loss: fit {fm['fit']:.6g}, "
            f"export {fm['export']:.6g}"
        )
    a = r.get("appearance")
    if a is not None:
        if a["fit_vs_measurement"] is not None:
            out.append(
                f"appearance against the measurement: fit {_score(a['fit_vs_measurement'])}; "
                f"export {_score(a['export_vs_measurement'])}"
            )
        out.append(f"appearance of the export against the fit: {_score(a['export_vs_fit'])}")
        if a["note"]:
            out.append(f"appearance: {a['note']}")
    tried = r.get("candidates") or []
    if len(tried) > 1:
        key = "against the measurement" if a and a["export_vs_measurement"] else "against the fit"
        each = ", ".join(
            f"{c['refit_metric']} loss HDR-FLIP {c['hdr_flip']:.4f}"
            for c in tried
            if "hdr_flip" in c
        )
        out.append(f"refits tried ({key}): {each}; the lowest HDR-FLIP is exported")
    if "seconds" in r:
        out.append(f"refit took {r['seconds']:.2f} s")
    return out


def comment(suffix: str, text: str, body: str) -> str:
    """``body`` (a written file's text) with ``text`` added as a comment in the file's own
    syntax: XML (``.xml``, ``.mtlx``, after an XML declaration), ``#`` lines (``.pbrt``,
    ``.py``, after ``#usda 1.0`` in ``.usda``); other files unchanged."""
    if suffix in (".xml", ".mtlx"):
        block = "<!--\n" + text.replace("--", "- -") + "\n-->\n"
        if body.startswith("<?xml"):
            head, _, rest = body.partition("\n")
            return head + "\n" + block + rest
        return block + body
    if suffix in (".pbrt", ".py", ".usda"):
        block = "".join(f"# {line}\n" for line in text.split("\n"))
        if body.startswith("#usda"):
            head, _, rest = body.partition("\n")
            return head + "\n" + block + rest
        return block + body
    return body


def measurement_path(recorded: str | None, fit_path: Path | None) -> str | None:
    """The recorded measurement ``data.path`` as a readable path (relative paths tried from the
    working folder, then from the fit file's folder; an archive member ``FILE::NAME`` is
    readable when ``FILE`` is), or None."""
    if not recorded:
        return None
    file, sep, member = recorded.partition("::")
    p = Path(file)
    if not p.is_absolute() and not p.exists() and fit_path is not None:
        p = fit_path.parent / p
    if not p.exists():
        return None
    return str(p) + (sep + member if sep else "")
