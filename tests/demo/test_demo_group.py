"""The tests of this folder are one xdist work unit, so the worker that runs them builds the
reduced demo (the ``demo`` fixture, about 70 s) once for all of them."""

from __future__ import annotations

import pytest

pytestmark = pytest.mark.xdist_group("demo-e2e")


def test_the_demo_tests_are_one_xdist_work_unit(request):
    """Under ``--dist loadgroup`` the group must end the node id: the scheduler reads it there
    (``tests/conftest.py`` writes it). Without it each worker would build the demo."""
    if not request.config.getoption("loadgroup", False):
        pytest.skip("not a worker of a pytest -n N --dist loadgroup run")
    assert request.node.nodeid.endswith("@demo-e2e"), request.node.nodeid
