"""Export targets come from one registry (gonio.export.registry): a target is one module plus
one line there. A tiny target defined in the tests is picked up by ``gonio export --to`` (help,
run) and by the Python API (``export``, ``to_<target>``, ``TARGETS``) with no other file changed."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from gonio import export
from gonio.brdf import models
from gonio.cli import main
from gonio.export import registry
from tests.export.conftest import fit_record, write_record


@pytest.fixture
def tiny(monkeypatch):
    """The registry with the tiny target's line added."""
    lines = (*registry.TARGET_MODULES, "tests.export.tiny_target")
    monkeypatch.setattr(registry, "TARGET_MODULES", lines)
    return "tiny"


def test_a_target_in_the_tests_is_picked_up_by_the_cli_and_the_api(tmp_path, capsys, tiny):
    fit = write_record(tmp_path / "fit.json", fit_record(models.Lambert([0.5, 0.4, 0.3])))
    with pytest.raises(SystemExit):
        main(["export", "--help"])
    help_text = capsys.readouterr().out
    assert "  tiny      one line of text, albedo R G B (.tiny)." in help_text
    assert "usd or tiny (see below)" in " ".join(help_text.split())
    assert main(["export", str(fit), "--to", "tiny", "--out", str(tmp_path / "m.x"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["target"] == "tiny" and report["mapping"] == "exact"
    assert (tmp_path / "m.tiny").read_text() == "albedo 0.5 0.4 0.3\n"
    e = export.to_tiny(str(fit))
    assert e.text == "albedo 0.5 0.4 0.3\n" and export.to_tiny.__name__ == "to_tiny"
    assert export.export(str(fit), "tiny").files == e.files
    assert list(export.TARGETS)[-1] == "tiny" and "to_tiny" in export.__all__


def test_unregistered_targets_are_refused_and_builtin_ones_keep_their_functions(tmp_path):
    from gonio.errors import ParameterError

    assert registry.names() == ["mitsuba", "pbrt", "blender", "openpbr", "usd"]
    for name in registry.names():
        assert getattr(export, f"to_{name}").__name__ == f"to_{name}"
    with pytest.raises(AttributeError):
        export.to_tiny  # noqa: B018
    with pytest.raises(ParameterError, match="unknown export target 'tiny'; choose one of"):
        export.export({}, "tiny")


def test_a_target_module_must_declare_itself(monkeypatch):
    monkeypatch.setattr(registry, "TARGET_MODULES", ("gonio.export._lobes",))
    with pytest.raises(TypeError, match="does not define TARGET"):
        registry.targets()


#: ``gonio export --help`` in a fresh interpreter, then whether JAX was imported.
HELP_PROBE = """\
import sys
from gonio.cli import main
try:
    main(["export", "--help"])
except SystemExit:
    print("jax imported:", "jax" in sys.modules)
"""


def test_export_help_lists_the_targets_without_jax():
    run = subprocess.run([sys.executable, "-c", HELP_PROBE], capture_output=True, text=True)
    assert "  openpbr   MaterialX document" in run.stdout, run.stderr
    assert run.stdout.strip().endswith("jax imported: False"), run.stdout
