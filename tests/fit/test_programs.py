"""Fit programs kept on disk as exported modules (gonio.fit.programs)."""

from __future__ import annotations

import threading
import time
from concurrent.futures import ThreadPoolExecutor

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gonio.fit import optimize, programs
from gonio.fit.data import from_arrays
from gonio.fit.losses import get_loss
from gonio.fit.objective import Compiled, Problem
from gonio.fit.params import Layout
from gonio.fit.presets import build


@pytest.fixture()
def cache_dir(tmp_path):
    old = jax.config.jax_compilation_cache_dir
    jax.config.update("jax_compilation_cache_dir", str(tmp_path))
    try:
        yield tmp_path / programs.SUBDIR
    finally:
        jax.config.update("jax_compilation_cache_dir", old)


def _problem() -> Problem:
    rng = np.random.default_rng(3)
    wi = rng.normal(size=(300, 3))
    wo = rng.normal(size=(300, 3))
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]) + 0.3, np.abs(wo[:, 2]) + 0.3
    data = from_arrays(wi, wo, rng.random((300, 3)) + 0.1)
    tmpl, fixed, tied = build("lambert+cook-torrance")
    return Problem(Layout(tmpl, 3, fixed=fixed, tied=tied), get_loss("ngan"), data)


def _fresh(problem: Problem) -> Compiled:
    """New compiled functions, as a new process would build them."""
    return Compiled(problem.layout, problem.loss)


def test_program_is_written_then_loaded_with_the_same_values(cache_dir):
    pb = _problem()
    u = jnp.asarray(pb.layout.random_starts(2, 1)[1])
    args = (u, pb.arrays, pb.layout.template)
    first = _fresh(pb)
    want = first.normal(*args)
    assert first.normal.last_source == "exported"
    assert len(list(cache_dir.glob("normal-*.jaxexport"))) == 1
    again = _fresh(pb)
    got = again.normal(*args)
    assert again.normal.last_source == "loaded"
    for a, b in zip(want, got, strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    # and equal to the plain jitted function's values
    for a, b in zip(jax.jit(first.normal_raw)(*args), got, strict=True):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-12)


def test_other_shapes_and_losses_get_other_files(cache_dir):
    pb = _problem()
    u = jnp.asarray(pb.layout.random_starts(1, 0)[0])
    fns = _fresh(pb)
    fns.cost(u, pb.arrays, pb.layout.template)
    sub = pb.with_data(pb.data.subset(np.arange(100)))
    sub.chunk = pb.chunk
    fns.cost(u, sub.arrays, pb.layout.template)
    other = Problem(pb.layout, get_loss("low-e2"), pb.data)
    Compiled(pb.layout, other.loss).cost(u, other.arrays, pb.layout.template)
    assert len(list(cache_dir.glob("cost-*.jaxexport"))) == 3


def test_a_corrupt_or_foreign_file_is_ignored(cache_dir):
    pb = _problem()
    u = jnp.asarray(pb.layout.random_starts(1, 0)[0])
    args = (u, pb.arrays, pb.layout.template)
    want = float(_fresh(pb).cost(*args))
    (path,) = cache_dir.glob("cost-*.jaxexport")
    path.write_bytes(b"not a program")
    fns = _fresh(pb)
    assert float(fns.cost(*args)) == want
    assert fns.cost.last_source == "exported"  # rewritten
    # a truncated program (an interrupted copy) is refused and exported again
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    fns = _fresh(pb)
    assert float(fns.cost(*args)) == want
    assert fns.cost.last_source == "exported"


def test_no_cache_dir_writes_nothing():
    old = jax.config.jax_compilation_cache_dir
    jax.config.update("jax_compilation_cache_dir", None)
    try:
        assert programs.program_dir() is None
        pb = _problem()
        u = jnp.asarray(pb.layout.random_starts(1, 0)[0])
        fns = _fresh(pb)
        fns.cost(u, pb.arrays, pb.layout.template)
        assert fns.cost.last_source == ""  # the plain jitted function
    finally:
        jax.config.update("jax_compilation_cache_dir", old)


def test_source_hash_changes_the_file_name(cache_dir, monkeypatch):
    pb = _problem()
    u = jnp.asarray(pb.layout.random_starts(1, 0)[0])
    _fresh(pb).cost(u, pb.arrays, pb.layout.template)
    monkeypatch.setattr(programs, "_SOURCE_HASH", ["edited"])
    fns = _fresh(pb)
    fns.cost(u, pb.arrays, pb.layout.template)
    assert fns.cost.last_source == "exported"
    assert len(list(cache_dir.glob("cost-*.jaxexport"))) == 2


def _counting(monkeypatch, block: threading.Event | None = None) -> list[str]:
    """Count Program._resolve calls (optionally holding each until ``block`` is set)."""
    calls: list[str] = []
    real = programs.Program._resolve

    def resolve(self, *a):
        calls.append(self.name)
        if block is not None:
            assert block.wait(60)
        return real(self, *a)

    monkeypatch.setattr(programs.Program, "_resolve", resolve)
    return calls


def test_prepare_in_a_thread_serves_a_concurrent_call_once(cache_dir, monkeypatch):
    pb = _problem()
    u = jnp.asarray(pb.layout.random_starts(1, 0)[0])
    args = (u, pb.arrays, pb.layout.template)
    release = threading.Event()
    calls = _counting(monkeypatch, release)
    fns = _fresh(pb)
    with ThreadPoolExecutor(2) as pool:
        ahead = pool.submit(fns.normal.prepare, *args)
        for _ in range(3000):  # until the preparing thread holds the signature
            if calls:
                break
            time.sleep(0.01)
        caller = pool.submit(fns.normal, *args)
        time.sleep(0.2)
        assert not caller.done()  # waits for the preparing thread instead of compiling
        release.set()
        ahead.result()
        got = caller.result()
    assert calls == ["normal"]
    for a, b in zip(jax.jit(fns.normal_raw)(*args), got, strict=True):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-12)


def test_a_failed_prepare_is_retried_by_the_next_call(cache_dir, monkeypatch):
    pb = _problem()
    u = jnp.asarray(pb.layout.random_starts(1, 0)[0])
    args = (u, pb.arrays, pb.layout.template)
    real = programs.Program._resolve
    fail = [True]

    def resolve(self, *a):
        if fail.pop() if fail else False:
            raise MemoryError("compiler ran out of memory")
        return real(self, *a)

    monkeypatch.setattr(programs.Program, "_resolve", resolve)
    fns = _fresh(pb)
    with pytest.raises(MemoryError):
        fns.cost.prepare(*args)
    assert float(fns.cost(*args)) == float(jax.jit(fns.cost_raw)(*args))


def test_problem_prepare_compiles_without_running(cache_dir, monkeypatch):
    pb = _problem()
    calls = _counting(monkeypatch)
    pb.fns = _fresh(pb)
    pb.prepare("hessian", "value_and_grad_scored")
    assert calls == ["hessian", "value_and_grad_scored"]
    assert pb._scored is None  # prepared, not run
    u = pb.layout.random_starts(1, 0)[0]
    pb.hessian(u)
    pb.value_and_grad_scored(u)
    assert calls == ["hessian", "value_and_grad_scored"]  # the calls reused them


def test_leaving_a_fit_cancels_the_compilations_not_started(monkeypatch):
    pb = _problem()
    started: list[tuple[str, ...]] = []
    gate = threading.Event()

    def prepare(self, *names):
        started.append(names)
        assert gate.wait(60)

    monkeypatch.setattr(Problem, "prepare", prepare)
    with pytest.raises(KeyboardInterrupt), optimize._compiled_ahead(pb, pb):
        for _ in range(3000):  # until both threads hold a job; two more are queued
            if len(started) == 2:
                break
            time.sleep(0.01)
        raise KeyboardInterrupt
    gate.set()
    optimize._compile_pool().submit(lambda: None).result()  # the pool has run all it will run
    assert started == [("normal",), ("value_and_grad",)]
