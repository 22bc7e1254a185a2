"""The documentation site builds with ``mkdocs build --strict``: a broken link, a missing page
or a reference that does not resolve fails the test run."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytest.importorskip("mkdocs", reason="mkdocs is not installed (the test extra installs it)")
pytest.importorskip("material", reason="mkdocs-material is not installed")
pytest.importorskip("mkdocstrings", reason="mkdocstrings is not installed")


def test_site_builds_strict(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"), NO_MKDOCS_2_WARNING="1")
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    site = tmp_path / "site"
    assert (site / "index.html").is_file()
    cli = (site / "cli" / "index.html").read_text(encoding="utf-8")
    commands = ("gonio fit", "gonio render", "gonio acquire", "gonio export", "gonio rig check")
    for command in commands:
        assert command in cli, f"the CLI reference lacks {command!r}"
    assert "render_sphere" in (site / "api" / "render" / "index.html").read_text(encoding="utf-8")
    assert "table:first_image" in (site / "performance" / "index.html").read_text(encoding="utf-8")
