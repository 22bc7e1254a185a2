"""The fit's compiled programs, kept on disk as serialized ``jax.export`` modules between runs.

JAX's persistent compilation cache (:mod:`gonio.compile_cache`) skips only XLA's compilation:
a new process still traces each jitted function to a jaxpr and lowers it to StableHLO, which
for the fit's programs (the normal equations on two data sizes, the gradient on every cell, the
subset's Hessian, the score pass) is a sizeable part of a cold ``gonio fit`` that the cache
cannot save, paid again by every new process. A :class:`Program` exports its function once
per argument signature, stores the serialized module, and in later processes deserializes it and
calls it (the call lowers to the stored module, which the compilation cache then finds).

Where: ``<JAX compilation cache dir>/gonio-fit-programs/`` (the folder
:func:`gonio.compile_cache.enable` sets for the commands); when no cache directory is set (a
library user who did not turn the cache on), a :class:`Program` is a plain ``jax.jit`` and
writes nothing. A file's name is a SHA-256 of everything the traced program depends on: the
program's name and its static key (model structure, fitted parameters, loss), the arguments'
tree structure, shapes and dtypes, the JAX and jaxlib versions, the backend, the x64 flag and
the contents of every ``.py`` file of the installed ``gonio`` package, so an edited model or
loss never reuses a stale program. A file that cannot be read, written or deserialized is
ignored (the function is traced as usual): the files only save time.

Format: JAX's own serialization of the :class:`jax.export.Exported` object
(``Exported.serialize``, a flatbuffer of the StableHLO module and its calling convention; the
``flatbuffers`` package is a dependency for it). Deserializing executes nothing; the folder is
trusted as JAX's compilation cache beside it is, whose files are native code.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import tempfile
import threading
from collections.abc import Callable
from concurrent.futures import Future
from pathlib import Path
from typing import Any

import jax
import numpy as np

#: Subfolder of the compilation cache directory holding the serialized programs.
SUBDIR = "gonio-fit-programs"

_SOURCE_HASH: list[str] = []


def source_hash() -> str:
    """SHA-256 of the path and contents of every ``.py`` file of the ``gonio`` package."""
    if not _SOURCE_HASH:
        root = Path(__file__).resolve().parents[1]
        h = hashlib.sha256()
        for p in sorted(root.rglob("*.py")):
            h.update(str(p.relative_to(root)).encode())
            h.update(p.read_bytes())
        _SOURCE_HASH.append(h.hexdigest())
    return _SOURCE_HASH[0]


def program_dir() -> Path | None:
    """Where programs are kept, or None when JAX has no compilation cache directory."""
    base = jax.config.jax_compilation_cache_dir
    return Path(base) / SUBDIR if base else None


class Program:
    """``jax.jit(fn)`` whose traced and lowered form is kept on disk (module docstring).

    Parameters
    ----------
    name : a name for the program (part of the file key).
    fn : the function; its arguments are pytrees of arrays, its outputs arrays or tuples of them.
    key : a ``repr``-stable description of everything ``fn`` closes over that changes what it
        computes (model structure, loss, ...).
    """

    def __init__(self, name: str, fn: Callable[..., Any], key: str) -> None:
        self.name, self.fn, self.key = name, fn, key
        self.jitted = jax.jit(fn, compiler_options=compiler_options())
        # signature -> the compiled callable, a Future while one thread resolves it (another
        # thread calling the same signature waits for it instead of compiling it again)
        self._calls: dict[Any, Future[Callable[..., Any]]] = {}
        self._lock = threading.Lock()
        #: how the last new signature was served: "loaded", "exported" or "jit"
        self.last_source = ""

    def __call__(self, *args: Any) -> Any:
        where = program_dir()
        if where is None:
            return self.jitted(*args)
        leaves, call = self._resolved(where, args)
        return call(*leaves)

    def prepare(self, *args: Any) -> None:
        """Load or trace, and compile, the program for the signature of ``args`` without
        running it; a later call with that signature (from any thread) waits for this one.

        Meant for a background thread ahead of the first call: XLA's compilation releases
        the GIL, so on a cold cache it overlaps with the caller's other work. Nothing happens
        without a program directory (a plain ``jax.jit`` compiles at its first call)."""
        where = program_dir()
        if where is not None:
            self._resolved(where, args)

    def _resolved(self, where: Path, args: Any) -> tuple[list[Any], Callable[..., Any]]:
        leaves, tree = jax.tree_util.tree_flatten(args)
        sig = (tree, tuple((np.shape(x), _dtype(x)) for x in leaves), str(where))
        with self._lock:
            pending = self._calls.get(sig)
            mine = pending is None
            if mine:
                pending = self._calls[sig] = Future()
        if mine:
            try:
                call = self._resolve(where, tree, leaves)
                call.lower(*leaves).compile()  # the jitted call reuses this executable
            except BaseException as exc:
                with self._lock:
                    del self._calls[sig]  # a later call tries again
                pending.set_exception(exc)
                raise
            pending.set_result(call)
        return leaves, pending.result()

    def _file(self, where: Path, tree: Any, leaves: list[Any]) -> Path:
        specs = [(np.shape(x), str(_dtype(x))) for x in leaves]
        import jaxlib

        versions = (jax.__version__, jaxlib.__version__, jax.default_backend())
        text = repr((self.name, self.key, repr(tree), specs, versions,
                     bool(jax.config.jax_enable_x64), source_hash()))  # fmt: skip
        return where / f"{self.name}-{hashlib.sha256(text.encode()).hexdigest()[:32]}.jaxexport"

    def _resolve(self, where: Path, tree: Any, leaves: list[Any]) -> Any:
        def flat(*xs: Any) -> Any:
            return self.fn(*jax.tree_util.tree_unflatten(tree, xs))

        path = self._file(where, tree, leaves)
        try:
            exp = jax.export.deserialize(bytearray(path.read_bytes()))
            self.last_source = "loaded"
        except Exception:  # absent, unreadable or from another version: export it again
            try:
                specs = [jax.ShapeDtypeStruct(np.shape(x), _dtype(x)) for x in leaves]
                exp = jax.export.export(jax.jit(flat))(*specs)
                _write(path, bytes(exp.serialize()))  # no VJP: the programs are not differentiated
                self.last_source = "exported"
            except Exception:  # a program JAX cannot export: trace it every process
                self.last_source = "jit"
                return jax.jit(flat, compiler_options=compiler_options())
        return jax.jit(exp.call, compiler_options=compiler_options())


def compiler_options() -> dict[str, Any]:
    """XLA options of the fit's programs: on the CPU, XLA's loop emitters instead of its MLIR
    fusion emitters, which take longer to compile these programs and run them slower: both a
    first fit on an empty compilation cache and a warm fit are faster with the loop emitters.
    Not set for the render kernels, whose cold first image is slower with it
    (``benchmarks/bench_first_image.py``)."""
    return {"xla_cpu_use_fusion_emitters": False} if jax.default_backend() == "cpu" else {}


_MODEL_VALUES: list[Any] = []


def model_f(model: Any, wi: Any, wo: Any) -> np.ndarray:
    """``model.f(wi, wo)`` of a gonio model (a JAX pytree) in sr^-1, ``(N, 3), (N, 3) -> (N, C)``,
    as one compiled program per model structure and N, with the fit's compiler options: one
    compilation instead of one per operation and shape when evaluated op by op."""
    if not _MODEL_VALUES:
        _MODEL_VALUES.append(
            jax.jit(lambda m, a, b: m.f(a, b), compiler_options=compiler_options())
        )
    return np.asarray(_MODEL_VALUES[0](model, np.asarray(wi), np.asarray(wo)))


def _dtype(x: Any) -> Any:
    return x.dtype if hasattr(x, "dtype") else np.result_type(x)


def _write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (a concurrent reader never sees a partial file);
    errors are ignored (the file only saves time)."""
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-")
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except OSError:  # a full disk: no partial file left in the cache either
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
