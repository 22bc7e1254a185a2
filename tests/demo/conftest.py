"""The reduced demo run shared by the tests of this folder (``xdist_group("demo-e2e")``)."""

from __future__ import annotations

import pytest

from gonio.demo import DemoSettings, builtin_material, run_demo


# session scope: xdist may run another module's tests between these in the same worker, which
# would tear a module-scoped fixture down and run the demo twice
@pytest.fixture(scope="session")
def demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo") / "gonio-demo"
    material = builtin_material()
    summary = run_demo(out, material, DemoSettings.quick(resolution=64, spp=8), progress=False)
    return out, material, summary
