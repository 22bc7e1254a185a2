"""Registers the rig-file JSON Schema (:func:`gonio.rigs.config.rig_schema`) with the project's
schema generator (``python -m gonio.io.schemas --write`` writes data-schema/rig.schema.json)."""

from __future__ import annotations

from gonio.io.schemas import register_schema
from gonio.rigs.config import rig_schema

register_schema("rig.schema.json")(rig_schema)
