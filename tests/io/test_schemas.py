"""data-schema/*.schema.json are generated from the code; committed copies must be current."""

from __future__ import annotations

import json

from gonio.io import schemas


def test_committed_schemas_are_not_stale():
    stale = schemas.stale()
    assert not stale, f"run `python -m gonio.io.schemas --write`: stale {stale}"


def test_registry_is_one_line_to_extend(tmp_path):
    @schemas.register_schema("zz-test.schema.json")
    def _s():
        return {"type": "object", "properties": {"a": {"type": "integer"}}}

    try:
        assert "zz-test.schema.json" in schemas.generate_all()
        assert schemas.stale(tmp_path) == sorted(schemas.generate_all())  # nothing written yet
        schemas.write_all(tmp_path)
        assert schemas.stale(tmp_path) == []
        doc = json.loads((tmp_path / "zz-test.schema.json").read_text())
        assert doc["$schema"] == schemas.DIALECT
        (tmp_path / "zz-test.schema.json").write_text("{}\n")
        assert schemas.stale(tmp_path) == ["zz-test.schema.json"]
    finally:
        schemas._REGISTRY.pop("zz-test.schema.json")


def test_every_schema_is_a_valid_json_schema():
    import jsonschema

    for schema in schemas.generate_all().values():
        jsonschema.Draft202012Validator.check_schema(schema)
