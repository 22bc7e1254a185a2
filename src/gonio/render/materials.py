"""What the renderer asks of a material: is it a table, its channels, delta lobes, and cutting
it down to the channels an image needs."""

from __future__ import annotations

from typing import Any

import numpy as np

from gonio.brdf.models import BRDFModel
from gonio.errors import ParameterError


def is_table(material: Any) -> bool:
    """A gridded table (has ``values``), as opposed to an analytic or self-sampling model."""
    return not isinstance(material, BRDFModel) and hasattr(material, "values")


def material_channels(material: Any) -> int:
    """Number of channels C of a model (``.channels`` int) or a table (``values.shape[-1]``)."""
    if isinstance(material, BRDFModel):
        return int(material.channels)
    values = getattr(material, "values", None)
    if values is not None:
        return int(np.shape(values)[-1])
    raise ParameterError(f"not a BRDF model or table: {type(material).__name__}")


def material_channel_names(material: Any) -> tuple[str, ...] | None:
    """Channel names of a table (``channels.names``) or None."""
    ch = getattr(material, "channels", None)
    names = getattr(ch, "names", None)
    return tuple(names) if names is not None else None


def has_delta(material: Any) -> bool:
    """The material is, or contains, a delta lobe (a mirror) that only BRDF sampling finds."""
    if getattr(material, "is_delta", False):
        return True
    return bool(getattr(material, "has_delta", False))


def restrict_model_channels(model: BRDFModel, idx: np.ndarray) -> BRDFModel:
    """The model with every per-channel parameter cut down to channels ``idx``.

    Evaluating only the channels asked for: per-channel parameters of length C become length
    ``len(idx)``; scalar (grey) parameters stay. Models whose channels are not parameters
    (a measured file, :class:`gonio.io.rgl_measured.RGLMeasured`) cut themselves
    (``select_channels``).
    """
    if hasattr(model, "select_channels"):
        return model.select_channels(idx)
    specs = model.param_specs()
    new = {}
    for key, value in model.params().items():
        v = np.asarray(value)
        if specs[key].per_channel and v.ndim == 1 and v.size > 1:
            new[key] = v[idx]
    return model.replace(**new) if new else model


def restrict_table_channels(table: Any, idx: np.ndarray) -> Any | None:
    """A table with only the channels ``idx`` (values, sigma and channel description cut), or
    None when the selection has no :class:`~gonio.brdf.tabulated.Channels` description (two
    channels of an RGB table): the caller then renders every channel and cuts afterwards.
    """
    ch = table.channels
    names = tuple(ch.names[i] for i in idx)
    if ch.kind == "spectral":
        new = type(ch)("spectral", names=names, wavelengths_nm=np.asarray(ch.wavelengths_nm)[idx])
    elif len(idx) == 1:
        new = type(ch)("mono", names=names)
    elif list(idx) == list(range(len(ch.names))):
        return table
    else:
        return None
    sigma = None if table.sigma is None else np.asarray(table.sigma)[..., idx]
    return table.replace(values=np.asarray(table.values)[..., idx], sigma=sigma, channels=new)
