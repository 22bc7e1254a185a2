"""Shared test configuration: paths to the third-party data in ../shared/data."""

from __future__ import annotations

import collections
import inspect
import os
import shutil
import sys
import tempfile
from pathlib import Path

import pytest

# Commands run in-process by the tests (gonio.cli.main) would otherwise turn on JAX's persistent
# compilation cache for the rest of the session and write into the user's cache directory;
# tests/test_compile_cache.py checks the cache in child processes without this variable.
os.environ.setdefault("GONIO_COMPILE_CACHE", "0")

# ------------------------------------------------------------------ one BLAS thread per process
# The suite runs one process per core (``-n 2`` on 2 cores), so BLAS threads only oversubscribe
# the cores; and OpenBLAS wakes its thread pool for every tiny LAPACK call, which is what
# scipy.spatial.Delaunay's barycentric transforms make, one per simplex (the scattered-data
# interpolant of gonio.brdf.gridding): 37,305 simplices took 5.3 s of CPU (24 s wall at load 20)
# with OpenBLAS's default threads and 0.07 s (0.5 s wall) with one. Set before NumPy is imported
# (no plugin imports it earlier), so it also reaches xdist workers and the tests' child
# processes; a caller's own value is kept.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

# ------------------------------------------------------------------ quicker XLA compilation
# Most of the suite's time is XLA compiling small programs once each. The tests run XLA's CPU
# code generation without LLVM's expensive optimization passes (the HLO optimizations, fusion
# included, are unchanged; IEEE semantics are kept, fast math stays off): two compile-bound
# tests of tests/io took 35-38 % less wall time in alternating rounds at load 13-15 (121 -> 83 s,
# 64 -> 40 s). GONIO_TEST_XLA_OPT=1 keeps XLA's full optimization (what users run); a caller's
# own XLA_FLAGS are kept, and extended only where they do not set the level themselves. Set
# before JAX creates its CPU backend (on first use), so it also reaches xdist workers and the
# tests' child processes through the environment.
#
# XLA's CPU fusion emitters (an MLIR pipeline run for every fusion) are most of what is left of
# a compile: the tests emit fusions with XLA's older LLVM IR emitters instead (the HLO and its
# fusions are unchanged, so are IEEE semantics), which takes about 40 % less CPU time on the
# compile-bound tests. XLA aborts on a flag it does not know and jaxlib releases before 0.7 may not
# know this one, so it is added from jaxlib 0.7 on; a caller's own setting of it is kept.
FAST_COMPILE_FLAGS = "--xla_backend_optimization_level=0 --xla_llvm_disable_expensive_passes=true"
LEGACY_EMITTER_FLAG = "--xla_cpu_use_fusion_emitters=false"


def _jaxlib_at_least(major: int, minor: int) -> bool:
    from importlib.metadata import PackageNotFoundError, version

    try:
        parts = version("jaxlib").split(".")[:2]
        return tuple(int("".join(c for c in p if c.isdigit()) or 0) for p in parts) >= (
            major,
            minor,
        )
    except (PackageNotFoundError, ValueError):
        return False


if os.environ.get("GONIO_TEST_XLA_OPT", "").strip().lower() not in ("1", "true", "yes", "on"):
    _flags = os.environ.get("XLA_FLAGS", "")
    if "xla_backend_optimization_level" not in _flags:
        _flags = f"{_flags} {FAST_COMPILE_FLAGS}".strip()
    if "xla_cpu_use_fusion_emitters" not in _flags and _jaxlib_at_least(0, 7):
        _flags = f"{_flags} {LEGACY_EMITTER_FLAG}"
    os.environ["XLA_FLAGS"] = _flags

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data"

# ------------------------------------------------------------------ one compilation cache per run
# Many tests compile the same XLA programs again: a new closure or model object is a new jit cache
# entry in memory, each xdist worker compiles for itself, and every ``python -m gonio`` child
# starts from nothing. One JAX persistent compilation cache in a temporary folder, made by the
# controlling process and handed to the workers and their children through JAX's own environment
# variables, lets each distinct program compile once per run. It holds nothing between runs (a
# fresh run compiles everything, as CI does) and it changes no result: JAX keys an entry by the
# program, the compile options, the JAX/XLA versions and the device. It is off by default:
# two full default runs of the same commit on a fresh clone took 1334 s with it and 1160 s
# without (GONIO_TEST_COMPILE_CACHE=0), so its gain is not shown; GONIO_TEST_COMPILE_CACHE=1
# turns it on. Tests that count compilations count cache hits too (tests/render/
# test_device_resident.py); tests/test_compile_cache.py gives its children a clean environment.
TEST_CACHE_VAR = "GONIO_TEST_COMPILE_CACHE"
JAX_CACHE_VARS = ("JAX_COMPILATION_CACHE_DIR", "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS")
#: Programs that compile faster than this are not written (reading one back costs ~10 ms).
CACHE_MIN_COMPILE_S = "0.1"


def pytest_configure(config: pytest.Config) -> None:
    if os.environ.get("PYTEST_XDIST_WORKER") or os.environ.get(JAX_CACHE_VARS[0]):
        return  # a worker (its controller made the folder) or a cache chosen by the caller
    if os.environ.get(TEST_CACHE_VAR, "").strip().lower() not in ("1", "true", "yes", "on"):
        return
    folder = tempfile.mkdtemp(prefix="gonio-test-jax-cache-")
    config.add_cleanup(lambda: shutil.rmtree(folder, ignore_errors=True))
    os.environ[JAX_CACHE_VARS[0]] = folder
    os.environ[JAX_CACHE_VARS[1]] = CACHE_MIN_COMPILE_S
    if "jax" in sys.modules:  # imported by a plugin already: the variables were read
        import jax

        jax.config.update("jax_compilation_cache_dir", folder)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", float(CACHE_MIN_COMPILE_S))


def shared_file(*parts: str) -> Path:
    """Path of a file under ../shared/data, skipping the test cleanly when it is absent."""
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"shared data file not available: {path}")
    return path


# ------------------------------------------------------------------------ xdist work units
# Under ``pytest -n 2 --dist loadgroup`` (``make test``) every test is its own work unit unless
# it carries ``xdist_group``, so a module- or session-scoped fixture is built again in each worker
# that happens to run one of its tests (the reduced demo twice: about 70 s each on this machine).
# The hook below puts the tests that share such a fixture of this suite into one group (joined
# with any ``xdist_group`` mark they carry), and writes the group into the test's node id, which
# is what the loadgroup scheduler reads. pytest-xdist 3.8 writes it into ``item._nodeid``, which
# pytest 9.2's structured node ids no longer read (pytest-xdist issue 1386): without this hook
# the marks group nothing.
_TESTS = Path(__file__).resolve().parent


def _marked_groups(item: pytest.Item) -> list[str]:
    return sorted(
        {
            str(m.args[0] if m.args else m.kwargs.get("name", "default"))
            for m in item.iter_markers("xdist_group")
        }
    )


def _shared_fixture_keys(item: pytest.Item) -> list[str]:
    """One key per instance of a non-function-scoped fixture of this suite that ``item`` uses."""
    info = getattr(item, "_fixtureinfo", None)
    if info is None:
        return []
    keys = []
    for name in item.fixturenames:
        defs = info.name2fixturedefs.get(name)
        if not defs or defs[-1].scope == "function":
            continue
        fixture = defs[-1]
        source = Path(inspect.getsourcefile(fixture.func) or "").resolve()
        if _TESTS not in source.parents:
            continue  # pytest's own (tmp_path_factory, ...): nothing expensive to share
        if fixture.scope in ("module", "class"):  # one instance per module (or class)
            keys.append(f"{item.nodeid.split('::')[0]}::{name}")
        else:  # session or package: one instance per worker
            keys.append(f"{source.relative_to(_TESTS.parent)}::{name}")
    return keys


def _set_group(item: pytest.Item, marked: list[str], group: str) -> None:
    nodeid = item.nodeid
    suffix = "@" + "_".join(marked)
    if marked and nodeid.endswith(suffix):  # a pytest or xdist where the mark already took
        nodeid = nodeid[: -len(suffix)]
    if hasattr(item, "_id"):  # pytest >= 9.2: the structured id; parse keeps the string as is
        item._id = type(item._id).parse(f"{nodeid}@{group}")
    else:
        item._nodeid = f"{nodeid}@{group}"


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Group the tests that share an expensive fixture for ``--dist loadgroup`` (see above)."""
    if not config.getoption("loadgroup", False):
        return  # not an xdist worker of a loadgroup run
    parent: dict[str, str] = {}

    def root(key: str) -> str:
        while parent.setdefault(key, key) != key:
            key = parent[key]
        return key

    marked = {item: _marked_groups(item) for item in items}
    keys = {item: [f"@{g}" for g in marked[item]] + _shared_fixture_keys(item) for item in items}
    for item_keys in keys.values():
        for key in item_keys[1:]:
            parent[root(key)] = root(item_keys[0])
    users: collections.Counter[str] = collections.Counter()  # tests per component
    names: dict[str, set[str]] = collections.defaultdict(set)  # its xdist_group marks
    for item in items:
        if keys[item]:
            users[root(keys[item][0])] += 1
            names[root(keys[item][0])].update(marked[item])
    for item in items:
        if marked[item]:
            _set_group(item, marked[item], "_".join(marked[item]))
        elif keys[item] and users[top := root(keys[item][0])] > 1:
            _set_group(item, [], min(names[top]) if names[top] else top)
