"""Registers the fit-result JSON Schema (:data:`gonio.fit.result.SCHEMA`) with the project's
schema generator (``python -m gonio.io.schemas --write`` writes data-schema/fit-result.schema.json).
"""

from __future__ import annotations

from typing import Any

from gonio.fit.result import SCHEMA
from gonio.io.schemas import register_schema


@register_schema("fit-result.schema.json")
def fit_result_schema() -> dict[str, Any]:
    """The schema of a ``gonio fit`` result file."""
    return dict(SCHEMA)
