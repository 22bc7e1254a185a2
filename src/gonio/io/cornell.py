"""Cornell / pbrt-v2 ``.brdf`` spectral gonioreflectometer samples.

Text format: ``#`` comment lines; the number of wavelengths ``n``; ``n`` wavelengths (nm); then
records ``theta_i phi_i theta_s phi_s v_1 .. v_n`` (angles in radians, values f_r in 1/sr, not
cosine-weighted). Numbers may be split over lines arbitrarily (the files wrap the wavelength list).
``theta_i, phi_i`` give gonio's ``wi`` (toward the light), ``theta_s, phi_s`` give ``wo``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gonio.io._common import PathLike, fail, read_text
from gonio.io._geometry import spherical
from gonio.io._sanity import check_brdf_values, check_channel_count
from gonio.io._text import MAX_TEXT_ROWS, NumberBlocks, check_line_count, numbered_lines


def parse_cornell_text(text: str, path: PathLike = "<text>") -> dict[str, Any]:
    """Parse Cornell ``.brdf`` text into plain arrays.

    Returns
    -------
    dict
        ``wavelengths_nm`` (n,), ``theta_i, phi_i, theta_s, phi_s`` (N,) radians,
        ``values`` (N, n) in 1/sr, ``comments`` (list of str).
    """
    comments: list[str] = []
    check_line_count(path, text)
    lines = NumberBlocks(path, "line")
    first = ""
    for lineno, line in numbered_lines(text):
        s = line.strip()
        if s.startswith("#"):
            comments.append(s[1:].strip())
        elif s:
            first = first or s.split()[0]
            lines.add(lineno, s)
    if not first:
        raise fail(path, "empty Cornell BRDF file (no numbers)")
    nums = lines.numbers()  # a bad token: "line N: not a number: 'x'"
    n_wl = nums[0]
    if not (np.isfinite(n_wl) and n_wl == int(n_wl) and n_wl >= 1):
        raise fail(path, f"impossible number of wavelengths {first!r}")
    check_channel_count(path, int(n_wl), "wavelengths")
    n_wl = int(n_wl)
    if len(nums) < 1 + n_wl:
        raise fail(path, f"truncated: {n_wl} wavelengths announced, {len(nums) - 1} numbers found")
    wl = nums[1 : 1 + n_wl]
    if not np.all(np.isfinite(wl)) or np.any(wl <= 0) or np.any(np.diff(wl) <= 0):
        raise fail(path, "wavelengths must be positive and strictly increasing")
    body = nums[1 + n_wl :]
    width = 4 + n_wl
    if body.size == 0:
        raise fail(path, "no sample records")
    if body.size % width:
        raise fail(
            path,
            f"truncated or malformed: {body.size} numbers after the header is not a multiple of "
            f"the record length {width}",
        )
    if body.size // width > MAX_TEXT_ROWS:
        raise fail(path, f"{body.size // width} sample records, more than {MAX_TEXT_ROWS}")
    rec = body.reshape(-1, width)
    if not np.all(np.isfinite(rec)):
        raise fail(path, "NaN or Inf in sample records")
    ang = rec[:, :4]
    if np.any(ang[:, [0, 2]] < 0) or np.any(ang[:, [0, 2]] > np.pi / 2 + 1e-6):
        raise fail(path, "polar angles outside [0, pi/2] (records must be in radians)")
    if np.any(np.abs(ang[:, [1, 3]]) > 4 * np.pi):
        raise fail(path, "azimuths outside [-4 pi, 4 pi] (records must be in radians)")
    check_brdf_values(path, "sample values", rec[:, 4:])  # f_r: finite, >= 0, not absurd
    return {
        "wavelengths_nm": wl,
        "theta_i": ang[:, 0],
        "phi_i": ang[:, 1],
        "theta_s": ang[:, 2],
        "phi_s": ang[:, 3],
        "values": rec[:, 4:],
        "comments": comments,
    }


def read_cornell(path: PathLike, color: str = "spectral", illuminant: str = "D65") -> Any:
    """Read a Cornell ``.brdf`` file as :class:`MeasuredSamples`.

    Parameters
    ----------
    color : {"spectral", "rgb"}
        Keep the spectral channels, or convert to linear sRGB through CIE 1931 XYZ.
    illuminant : {"D65", "E"}
        Illuminant of the spectral -> RGB conversion (see :mod:`gonio.io.spectral`).
    """
    from gonio.brdf.measured import MeasuredSamples
    from gonio.brdf.tabulated import Channels
    from gonio.errors import ParameterError
    from gonio.io import spectral

    d = parse_cornell_text(read_text(path), path)
    wi = spherical(d["theta_i"], d["phi_i"])
    wo = spherical(d["theta_s"], d["phi_s"])
    meta: dict[str, Any] = {
        "source": {
            "format": "cornell",
            "file": str(path),
            "description": _description(d["comments"]),
        }
    }
    if color == "spectral":
        values = d["values"]
        channels = Channels.spectral(d["wavelengths_nm"])
    elif color == "rgb":
        values = spectral.spectrum_to_linear_srgb(d["values"], d["wavelengths_nm"], illuminant)
        channels = Channels.rgb()
        meta["source"]["color_conversion"] = f"CIE 1931 2-degree, illuminant {illuminant}, sRGB"
    else:
        raise ParameterError(f"color must be 'spectral' or 'rgb', got {color!r}")
    return MeasuredSamples(
        wi=wi,
        wo=wo,
        values=np.asarray(values, dtype=np.float64),
        sigma=None,
        channels=channels,
        weights=None,
        meta=meta,
    )


#: Comment lines of a Cornell file that label its sections rather than describe the material.
_SECTION_LABELS = ("num wls", "wls", "theta i")


def _description(comments: list[str]) -> str:
    """The descriptive header comments (lab, material, finish), joined with " / "; the section
    labels that follow them ("num wls", "wls", "theta i, phi i, ...") are left out."""
    keep = []
    for c in comments:
        text = c.strip().lstrip("#").strip()
        if text.lower().startswith(_SECTION_LABELS):
            break
        if text:
            keep.append(text)
    return " / ".join(keep)
