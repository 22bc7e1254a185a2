"""Channels of the material an image needs: picking them by index or name, and cutting the
material down to them. Every material answers the same questions
(:class:`gonio.brdf.material.Material`); nothing here asks what kind it is."""

from __future__ import annotations

from typing import Any

import numpy as np

from gonio.errors import ParameterError


def channel_index(material: Any, channels: Any, n: int) -> np.ndarray | None:
    """Indices of ``channels`` (None, an index, a name, or a list of them) among the ``n``
    channels of an image of ``material``; names are looked up in ``material.channel_info``."""
    if channels is None:
        return None
    info = material.channel_info
    names = None if info is None else tuple(info.names)
    items = [channels] if isinstance(channels, str | int | np.integer) else list(channels)
    idx = []
    for c in items:
        if isinstance(c, str):
            if names is None or c not in names:
                raise ParameterError(f"unknown channel {c!r}; the material has {names}")
            idx.append(names.index(c))
        else:
            i = int(c)
            if not 0 <= i < n:
                raise ParameterError(f"channel index {i} out of range for {n} channels")
            idx.append(i)
    if not idx:
        raise ParameterError("channels selects nothing")
    return np.asarray(idx, dtype=np.int64)


def restrict_channels(material: Any, idx: np.ndarray) -> Any | None:
    """``material`` evaluating only channels ``idx`` (itself when it has one channel, which
    serves every selection), or None when it cannot cut them: the caller then renders every
    channel and cuts afterwards."""
    if material.n_channels <= 1:
        return material
    return material.select_channels(idx)
