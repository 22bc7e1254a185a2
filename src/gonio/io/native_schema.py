"""JSON Schema of the native ``*.brdf.h5`` header (:func:`gonio.io.native.read_header`),
published as ``data-schema/table-metadata.schema.json`` (``python -m gonio.io.schemas``)."""

from __future__ import annotations

from gonio.io.native import (
    CHANNEL_KINDS,
    ENCODINGS,
    FORMAT_NAME,
    FORMAT_VERSION,
    INTERPOLATIONS,
    INVALID_VALUES,
    KINDS,
    PARAMETERIZATIONS,
    PROVENANCE_FIELDS,
    SUFFIX,
    UNITS,
    WARPS,
)
from gonio.io.schemas import register_schema


@register_schema("table-metadata.schema.json")
def table_metadata_schema() -> dict:
    """JSON Schema of :func:`read_header`'s result (the header of a ``*.brdf.h5`` file)."""
    num = {"type": "number"}
    axis = {
        "type": "object",
        "description": "A grid axis. Node i sits at x_i = (i + node_offset) / size; angle = "
        "lo + (hi - lo) * x (warp 'linear') or lo + (hi - lo) * x**2 (warp 'sqrt'), radians.",
        "required": ["name", "size", "lo", "hi", "warp", "periodic", "node_offset"],
        "additionalProperties": False,
        "properties": {
            "name": {"type": "string", "description": "theta_h, phi_h, theta_d or phi_d"},
            "size": {"type": "integer", "minimum": 1},
            "lo": {**num, "description": "radians"},
            "hi": {**num, "description": "radians"},
            "warp": {"enum": list(WARPS)},
            "periodic": {"type": "boolean"},
            "node_offset": num,
        },
    }
    provenance = {
        name: {"type": types if len(types) > 1 else types[0], "description": doc}
        for name, (types, doc) in PROVENANCE_FIELDS.items()
    }
    return {
        "$id": "https://gonio.invalid/schemas/table-metadata.schema.json",
        "title": "gonio tabulated BRDF header",
        "description": f"Header of a {SUFFIX} file (format {FORMAT_NAME} version "
        f"{FORMAT_VERSION}) as returned by gonio.io.native.read_header and 'gonio info --json'.",
        "type": "object",
        "required": [
            "format",
            "format_version",
            "kind",
            "units",
            "software",
            "created_utc",
            "channels",
            "datasets",
            "encoding",
            "metadata",
        ],
        "properties": {
            "format": {"const": FORMAT_NAME},
            "format_version": {"const": FORMAT_VERSION},
            "kind": {"enum": list(KINDS)},
            "units": {"const": UNITS},
            "software": {"type": "string"},
            "created_utc": {"type": "string", "description": "ISO 8601, UTC"},
            "channels": {
                "type": "object",
                "required": ["kind", "names", "primaries", "white_point", "wavelengths_nm"],
                "additionalProperties": False,
                "properties": {
                    "kind": {"enum": list(CHANNEL_KINDS)},
                    "names": {"type": "array", "items": {"type": "string"}, "minItems": 1},
                    "primaries": {"type": ["string", "null"], "description": "e.g. sRGB"},
                    "white_point": {"type": ["string", "null"], "description": "e.g. D65"},
                    "wavelengths_nm": {"type": ["array", "null"], "items": num},
                },
            },
            "grid": {
                "type": "object",
                "required": ["parameterization", "interpolation", "axes"],
                "additionalProperties": False,
                "properties": {
                    "parameterization": {"enum": list(PARAMETERIZATIONS)},
                    "interpolation": {"enum": list(INTERPOLATIONS)},
                    "axes": {"type": "array", "items": axis, "minItems": 1},
                    "invalid_values": {
                        "enum": list(INVALID_VALUES),
                        "description": "what /values holds at invalid nodes: zero, or a filled "
                        "table's extrapolation (/mask attribute invalid_values; absent = zero)",
                    },
                },
            },
            "samples": {
                "type": "object",
                "required": ["count"],
                "properties": {"count": {"type": "integer", "minimum": 0}},
            },
            "datasets": {"type": "array", "items": {"type": "string"}},
            "encoding": {
                "type": "object",
                "required": ["values"],
                "properties": {
                    "values": {"enum": list(ENCODINGS)},
                    "log_offset": num,
                    "log_step": {**num, "exclusiveMinimum": 0},
                    "floor": num,
                    "delta_axis": {"type": "integer", "minimum": 0},
                    "bound_relative": {**num, "description": "guaranteed max relative error"},
                    "requested_precision": num,
                    "achieved": {
                        "type": "object",
                        "properties": {
                            "median_relative": num,
                            "p99_relative": num,
                            "max_relative": num,
                        },
                    },
                },
            },
            "metadata": {
                "type": "object",
                "description": "Provenance. Recommended keys are listed; others are allowed.",
                "properties": provenance,
                "additionalProperties": True,
            },
        },
        "oneOf": [
            {"properties": {"kind": {"const": "gridded"}}, "required": ["grid"]},
            {"properties": {"kind": {"const": "scattered"}}, "required": ["samples"]},
        ],
    }


__all__ = ["table_metadata_schema"]
