"""The persistent compilation cache: where it lives, that commands use it, how to turn it off."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from gonio import compile_cache
from gonio.brdf.models import Lambert
from tests.conftest import JAX_CACHE_VARS


@pytest.mark.parametrize("value", ["0", "false", "OFF", "no"])
def test_environment_variable_turns_it_off(monkeypatch, value):
    monkeypatch.setenv(compile_cache.ENV_VAR, value)
    assert compile_cache.resolve() is None


def test_directory_follows_xdg_and_the_variable(monkeypatch, tmp_path):
    monkeypatch.delenv(compile_cache.ENV_VAR, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert compile_cache.resolve() == tmp_path / "gonio" / "jax"
    assert compile_cache.resolve(disabled=True) is None
    monkeypatch.setenv(compile_cache.ENV_VAR, str(tmp_path / "elsewhere"))
    assert compile_cache.resolve() == tmp_path / "elsewhere"


def _render(tmp_path: Path, cache_home: Path, *flags: str, **env: str) -> None:
    fit = tmp_path / "lambert.json"
    fit.write_text(json.dumps(Lambert(albedo=0.5).to_dict()))
    # without the test run's own cache (tests/conftest.py): the child sees a user's environment
    drop = {compile_cache.ENV_VAR, *JAX_CACHE_VARS}
    child_env = {k: v for k, v in os.environ.items() if k not in drop}
    child_env.update(XDG_CACHE_HOME=str(cache_home), JAX_PLATFORMS="cpu", **env)
    cmd = [sys.executable, "-m", "gonio", "render", "--fitted", str(fit), "--resolution", "8"]
    # the studio environment, not a directional light: JAX writes only kernels that compile
    # in MIN_COMPILE_SECONDS (0.1 s) or more, and the delta-light kernel takes 0.10-0.11 s on
    # a fast machine (nothing written: a flaky test); the environment's light stage takes 0.57
    cmd += ["--env", "studio", "--spp", "16", "--no-images", "--out", str(tmp_path / "x.png")]
    cmd += list(flags)
    subprocess.run(cmd, env=child_env, check=True, capture_output=True, timeout=300)


def test_render_command_writes_the_cache_and_the_flag_disables_it(tmp_path):
    on, off, env_off = tmp_path / "on", tmp_path / "off", tmp_path / "env-off"
    _render(tmp_path, on)
    entries = list((on / "gonio" / "jax").iterdir())
    assert entries, "no compiled kernel was written to the cache directory"
    _render(tmp_path, off, "--no-compile-cache")
    _render(tmp_path, env_off, **{compile_cache.ENV_VAR: "0"})
    assert not (off / "gonio").exists()
    assert not (env_off / "gonio").exists()
