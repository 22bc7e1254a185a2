"""The compiled objective: residuals, cost, gradient and normal equations of one fit problem.

``jax.jit`` sits here, at the objective boundary. The data travel as jit *arguments* (never as
closed-over constants, which XLA would embed in the program and recompile per material), padded
and split into equal chunks so that memory stays bounded on a full MERL table: the normal
equations ``A = J^T J`` (P x P) and ``g = J^T r`` are accumulated chunk by chunk with one
forward-mode Jacobian pass (``jacfwd``, P tangents) per chunk, so the cost in N is one pass;
likewise the gradient and the Hessian are sums of the chunks' gradients and Hessians in one
forward scan (:func:`chunk_sum`), not derivatives of the whole scan.
All arithmetic is float64. The programs every fit runs (cost, gradient, normal equations,
Hessian, score pass) are :class:`~gonio.fit.programs.Program` objects: ``jax.jit`` functions
whose traced form is kept on disk when a compilation cache directory is set.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from gonio.fit.data import FitData
from gonio.fit.losses import LOSSES, Loss, constants_of, data_constants
from gonio.fit.params import Layout
from gonio.fit.programs import Program

Array = jnp.ndarray

#: Rows per chunk of the accumulated normal equations.
DEFAULT_CHUNK = 32768


@dataclass
class Problem:
    """A fit problem: layout (which parameters, how mapped), loss and data, compiled.

    Attributes
    ----------
    layout, loss, data : the pieces.
    n_residuals : number M of residuals (valid samples times channels).
    arrays : the device-side data pytree passed to the compiled functions.
    """

    layout: Layout
    loss: Loss
    data: FitData
    chunk: int = DEFAULT_CHUNK

    def __post_init__(self) -> None:
        n = self.data.n
        k = max(1, -(-n // self.chunk))
        size = -(-n // k)  # equal chunks, at most `chunk` rows
        # round up so that data sets of similar size share compiled code
        size = min(-(-size // 256) * 256, max(self.chunk, 256))
        pad = k * size - n
        consts = self.loss.constants(self.data)
        up = np.array([0.0, 0.0, 1.0])

        def padded(a: np.ndarray, fill: Any) -> np.ndarray:
            if pad:
                extra = np.broadcast_to(np.asarray(fill, dtype=a.dtype), (pad, *a.shape[1:]))
                a = np.concatenate([a, extra])
            return a.reshape(k, size, *a.shape[1:])

        arrays = {
            "wi": padded(self.data.wi, up),
            "wo": padded(self.data.wo, up),
            "mask": padded(np.ones((n, 1)), 0.0),
            "k": {key: padded(v, 1.0 if key == "inv_sigma" else 0.0) for key, v in consts.items()},
        }
        self.arrays = jax.device_put(arrays)  # (jnp.asarray would compile a copy per shape)
        self.n_chunks, self.chunk_rows = k, size
        self.n_residuals = n * self.data.channels
        self.n_params = self.layout.size
        self._score_arrays: dict[str, Any] | None = None
        self._scored: tuple[np.ndarray, np.ndarray, int] | None = None
        self._build()

    # -- compiled functions ---------------------------------------------------------------------
    def _build(self) -> None:
        self.fns = compiled(self.layout, self.loss)

    # -- NumPy conveniences ---------------------------------------------------------------------
    def cost(self, u: np.ndarray) -> float:
        """``L = sum r^2`` at ``u``."""
        return float(self.fns.cost(jnp.asarray(u, jnp.float64), self.arrays, self.layout.template))

    def value_and_grad(self, u: np.ndarray) -> tuple[float, np.ndarray]:
        """``L`` and ``dL/du`` at ``u``."""
        v, g = self.fns.value_and_grad(
            jnp.asarray(u, jnp.float64), self.arrays, self.layout.template
        )
        return float(v), np.asarray(g)

    def value_and_grad_scored(self, u: np.ndarray) -> tuple[float, np.ndarray]:
        """:meth:`value_and_grad`, computing in the same pass the sums :meth:`scores` needs
        for every loss at ``u`` and keeping them (the last such point only): a fit whose last
        gradient pass is at its optimum then needs no separate score pass."""
        u = np.array(u, dtype=np.float64)
        (v, (sums, bad)), g = self.fns.value_and_grad_scored(
            jnp.asarray(u), self.arrays, self._score_data(), self.layout.template
        )
        self._scored = (u, np.asarray(sums), int(bad))
        return float(v), np.asarray(g)

    def normal(self, u: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """``(L, J^T r, J^T J)`` at ``u``."""
        s, g, a = self.fns.normal(jnp.asarray(u, jnp.float64), self.arrays, self.layout.template)
        return float(s), np.asarray(g), np.asarray(a)

    def hessian(self, u: np.ndarray) -> np.ndarray:
        """Exact Hessian ``d2L/du2`` (P x P)."""
        return np.asarray(
            self.fns.hessian(jnp.asarray(u, jnp.float64), self.arrays, self.layout.template)
        )

    def prepare(self, *names: str) -> None:
        """Compile (or load) the programs ``names`` (of ``"cost"``, ``"value_and_grad"``,
        ``"value_and_grad_scored"``, ``"normal"``, ``"hessian"``, ``"predict"``) for this
        problem's data without running them (:meth:`~gonio.fit.programs.Program.prepare`)."""
        u = jnp.zeros(self.n_params, jnp.float64)
        for name in names:
            extra = (self._score_data(),) if name == "value_and_grad_scored" else ()
            getattr(self.fns, name).prepare(u, self.arrays, *extra, self.layout.template)

    def residuals(self, u: np.ndarray) -> np.ndarray:
        """Residuals of the valid samples, (N, C)."""
        r = np.asarray(
            self.fns.residuals(jnp.asarray(u, jnp.float64), self.arrays, self.layout.template)
        )
        return r.reshape(-1, self.data.channels)[: self.data.n]

    def predict(self, u: np.ndarray) -> np.ndarray:
        """Model values at the data's directions, (N, C) in sr^-1."""
        f = np.asarray(
            self.fns.predict(jnp.asarray(u, jnp.float64), self.arrays, self.layout.template)
        )
        f = f.reshape(-1, f.shape[-1])[: self.data.n]
        return np.broadcast_to(f, (self.data.n, self.data.channels))

    def scores(self, u: np.ndarray, names: tuple[str, ...]) -> tuple[dict[str, float], int]:
        """The reported values of the losses ``names`` at ``u`` on the data, and the number of
        non-finite model values: one compiled pass over the chunks (no model values on the
        host; on a MERL table this replaces :meth:`predict` plus
        :func:`~gonio.fit.losses.evaluate_many`, equal to 1e-10). ``wls`` is the chi-square
        with the data's sigma (1 when absent)."""
        kept = self._scored
        if kept is not None and names == tuple(LOSSES) and np.array_equal(kept[0], u):
            sums, bad = kept[1], kept[2]
        else:
            sums, bad = self.fns.scores(names)(
                jnp.asarray(u, jnp.float64), self.arrays, self._score_data(), self.layout.template
            )
        total_w = float(np.sum(self.data.weights)) * self.data.channels
        out = {}
        for name, v in zip(names, np.asarray(sums), strict=True):
            lo = LOSSES[name]
            out[name] = lo.value(float(v) / (total_w if "scale" in lo.needs else 1.0))
        return out, int(bad)

    def _score_data(self) -> dict[str, Any]:
        if self._score_arrays is None:
            self._score_arrays = _score_arrays(self.data, self.n_chunks, self.chunk_rows)
        return self._score_arrays

    def cluster_scores(self, u: np.ndarray, ids: np.ndarray, n_clusters: int) -> np.ndarray:
        """``J_g^T r_g`` per cluster, ``(G, P)``, for sample cluster indices ``ids`` ``(N,)`` in
        ``[0, G)`` (the meat of a cluster-robust sandwich covariance)."""
        k, size = self.n_chunks, self.chunk_rows
        ids = np.asarray(ids, dtype=np.int32)
        pad = k * size - ids.size
        ids = np.concatenate([ids, np.zeros(pad, np.int32)]).reshape(k, size)  # mask zeroes pads
        out = self.fns.cluster_scores(
            jnp.asarray(u, jnp.float64), self.arrays, self.layout.template, jnp.asarray(ids),
            int(n_clusters),
        )  # fmt: skip
        return np.asarray(out)

    def with_data(self, data: FitData) -> Problem:
        """The same layout and loss on other data (e.g. a subsample)."""
        return Problem(self.layout, self.loss, data, self.chunk)


class Compiled:
    """Jitted functions of one (model structure, fitted parameters, loss) combination.

    Every function takes ``(u, arrays, template)``: the template model is an argument (a pytree)
    rather than a closed-over constant, so that fits of the same model structure to other data
    or from other templates reuse the compiled code.
    """

    def __init__(self, layout: Layout, loss: Loss) -> None:
        entries = layout.entries
        key = repr(_key(layout, loss))

        tied = dict(layout.tied)

        def to_model(u: Array, tmpl: Any) -> Any:
            parts = {}
            for e in entries:
                v = layout._forward(e, u[e.offset : e.offset + e.size])
                parts[e.key] = v.reshape(e.shape)
            for target, source in tied.items():
                parts[target] = parts[source]
            return tmpl.replace(**parts)

        def chunk_values(u: Array, c: dict[str, Any], tmpl: Any) -> tuple[Array, Array]:
            """One chunk's model values ``(rows, C)`` and masked residuals ``(rows * C,)``."""
            f = to_model(u, tmpl).f(c["wi"], c["wo"])
            return f, (loss.residual(f, c["k"]) * c["mask"]).reshape(-1)

        def chunk_res(u: Array, c: dict[str, Any], tmpl: Any) -> Array:
            return chunk_values(u, c, tmpl)[1]

        def chunk_cost(u: Array, c: dict[str, Any], tmpl: Any) -> Array:
            """One chunk's ``sum r^2``."""
            r = chunk_res(u, c, tmpl)
            return jnp.dot(r, r)

        def cost(u: Array, arrays: dict[str, Any], tmpl: Any) -> Array:
            return chunk_sum(lambda c: chunk_cost(u, c, tmpl), arrays)

        def value_and_grad(u: Array, arrays: dict[str, Any], tmpl: Any) -> tuple[Array, Array]:
            """``(L, dL/du)`` as sums of the chunks' values and gradients (see chunk_sum)."""
            return chunk_sum(lambda c: jax.value_and_grad(chunk_cost)(u, c, tmpl), arrays)

        def hessian(u: Array, arrays: dict[str, Any], tmpl: Any) -> Array:
            """``d2L/du2`` (P x P) as the sum of the chunks' Hessians (see chunk_sum)."""
            return chunk_sum(lambda c: jax.hessian(chunk_cost)(u, c, tmpl), arrays)

        def normal(u: Array, arrays: dict[str, Any], tmpl: Any) -> tuple[Array, Array, Array]:
            def one(c: dict[str, Any]) -> tuple[Array, Array, Array]:
                def res_aux(v: Array) -> tuple[Array, Array]:
                    r = chunk_res(v, c, tmpl)
                    return r, r

                jac, r = jax.jacfwd(res_aux, has_aux=True)(u)
                return jnp.dot(r, r), jac.T @ r, jac.T @ jac

            return chunk_sum(one, arrays)

        def cluster_scores(
            u: Array, arrays: dict[str, Any], tmpl: Any, ids: Array, n_clusters: int
        ) -> Array:
            n_ch = arrays["k"]["y"].shape[-1]

            def one(xs: tuple[dict[str, Any], Array]) -> Array:
                c, idc = xs
                jac = jax.jacfwd(lambda v: chunk_res(v, c, tmpl))(u)
                r = chunk_res(u, c, tmpl)
                rows = jnp.repeat(idc, n_ch)  # residual rows are (sample, channel) in C order
                return jax.ops.segment_sum(jac * r[:, None], rows, n_clusters)

            return chunk_sum(one, (arrays, ids))

        def residuals(u: Array, arrays: dict[str, Any], tmpl: Any) -> Array:
            return jax.vmap(lambda c: chunk_res(u, c, tmpl))(arrays).reshape(-1)

        def predict(u: Array, arrays: dict[str, Any], tmpl: Any) -> Array:
            model = to_model(u, tmpl)
            return jax.vmap(lambda c: model.f(c["wi"], c["wo"]))(arrays)

        def score_sums(f: Array, c: dict[str, Any], e: dict[str, Any], names: tuple[str, ...],
                       needs: tuple[str, ...]) -> tuple[Array, Array]:  # fmt: skip
            """One chunk's sums of squared residuals per loss (``scale`` = sqrt(w)) and its
            count of non-finite model values at valid samples."""
            y = e["y"]
            f = jnp.broadcast_to(f, y.shape)
            ok = jnp.isfinite(f)
            bad = jnp.sum(jnp.where(ok, 0.0, c["mask"]))
            f = jnp.where(ok, f, 0.0)
            k = {**constants_of(needs, y, e["inv_sigma"], e["w"], c["wi"][..., 2:3],
                                skip=tuple(e["k"])), **e["k"]}  # fmt: skip
            sums = jnp.stack(
                [jnp.sum((LOSSES[n]._residual(f, k, jnp) * c["mask"]) ** 2) for n in names]
            )
            return sums, bad

        def needs_of(names: tuple[str, ...]) -> tuple[str, ...]:
            return tuple(dict.fromkeys(k for n in names for k in LOSSES[n].needs))

        score_fns: dict[tuple[str, ...], Any] = {}

        def scores_fn(names: tuple[str, ...]) -> Any:
            """Jitted ``(u, arrays, extra, tmpl) -> (sums, n_bad)``: per loss the sum of squared
            residuals with ``scale`` = sqrt(w) (the caller divides by C W), and the count of
            non-finite model values at valid samples."""
            fn = score_fns.get(names)
            if fn is not None:
                return fn
            needs = needs_of(names)

            def run(u: Array, arrays: dict[str, Any], extra: dict[str, Any], tmpl: Any) -> Any:
                model = to_model(u, tmpl)

                def one(xs: Any) -> tuple[Array, Array]:
                    c, e = xs
                    return score_sums(model.f(c["wi"], c["wo"]), c, e, names, needs)

                return chunk_sum(one, (arrays, extra))

            fn = score_fns[names] = Program("scores", run, f"{key} {names}")
            return fn

        every = tuple(LOSSES)
        every_needs = needs_of(every)

        def chunk_cost_scored(u: Array, c: dict[str, Any], e: dict[str, Any], tmpl: Any) -> Any:
            """One chunk's ``sum r^2`` with, as auxiliary output, every loss's score sums at
            ``u`` (the score pass of the same model values, outside the gradient)."""
            f, r = chunk_values(u, c, tmpl)
            return jnp.dot(r, r), score_sums(jax.lax.stop_gradient(f), c, e, every, every_needs)

        def value_and_grad_scored(
            u: Array, arrays: dict[str, Any], extra: dict[str, Any], tmpl: Any
        ) -> Any:
            """``((L, (score sums, n_bad)), dL/du)``, summed over the chunks (see chunk_sum)."""
            vg = jax.value_and_grad(chunk_cost_scored, has_aux=True)
            return chunk_sum(lambda ce: vg(u, ce[0], ce[1], tmpl), (arrays, extra))

        self.scores = scores_fn
        self.to_model = to_model
        self.chunk_res = chunk_res
        self.cost_raw = cost
        self.normal_raw = normal
        # the programs of every fit: kept on disk when a compilation cache is set (programs.py)
        self.cost = Program("cost", cost, key)
        self.value_and_grad = Program("value_and_grad", value_and_grad, key)
        self.value_and_grad_scored = Program("value_and_grad_scored", value_and_grad_scored, key)
        self.normal = Program("normal", normal, key)
        self.hessian = Program("hessian", hessian, key)
        self.residuals = jax.jit(residuals)
        self.predict = Program("predict", predict, key)
        self.cluster_scores = jax.jit(cluster_scores, static_argnums=4)


#: Data-side constants of the score pass that cost a transcendental per value (computed once
#: per data set, not in every pass: about half of the pass's time with ``cube-root``).
_SCORE_CONSTANTS = ("log_y_cos", "log_y", "cbrt_y")
#: The score pass's padded data arrays of the last few data sets: ``id(data) -> (weak
#: reference to the data, chunking, arrays)`` (fits of several models to one table share them).
_SCORE_DATA: dict[int, tuple[Any, tuple[int, int], dict[str, Any]]] = {}


def _score_arrays(data: FitData, n_chunks: int, rows: int) -> dict[str, Any]:
    """The score pass's device arrays for ``data`` in ``n_chunks`` chunks of ``rows`` rows."""
    hit = _SCORE_DATA.get(id(data))
    if hit is not None and hit[0]() is data and hit[1] == (n_chunks, rows):
        return hit[2]
    pad = n_chunks * rows - data.n

    def padded(a: np.ndarray) -> Any:
        a = np.concatenate([a, np.zeros((pad, *a.shape[1:]), a.dtype)]) if pad else a
        return jax.device_put(a.reshape(n_chunks, rows, *a.shape[1:]))

    k = data_constants(_SCORE_CONSTANTS, data)
    arrays = {
        "y": padded(data.values),
        "w": padded(data.weights[:, None]),
        "inv_sigma": None if data.sigma is None else padded(1.0 / data.sigma),
        "k": {key: padded(k[key]) for key in _SCORE_CONSTANTS},
    }
    if len(_SCORE_DATA) >= 4:
        _SCORE_DATA.clear()
    _SCORE_DATA[id(data)] = (weakref.ref(data), (n_chunks, rows), arrays)
    return arrays


def chunk_sum(fn: Any, xs: Any) -> Any:
    """``sum_k fn(chunk k)`` over the leading (chunk) axis of the pytree ``xs``, in one forward
    ``jax.lax.scan`` whose carry holds the running sums (a pytree of ``fn``'s output structure).

    Every pass over the cells is one (cost, normal equations, score sums, cluster scores); the
    gradient and Hessian programs are built from it with ``fn`` a chunk's
    ``jax.value_and_grad`` or ``jax.hessian``, since the derivatives of a sum are the sums of
    the chunks' derivatives: differentiating the whole scan instead (``jax.grad`` of
    ``cost``) makes JAX keep every chunk's residuals for the backward pass and run a second,
    reverse scan over them; per-chunk accumulation needs one pass and one chunk's memory.
    """
    one = jax.tree_util.tree_map(lambda a: jax.ShapeDtypeStruct(a.shape[1:], a.dtype), xs)
    init = jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), jax.eval_shape(fn, one))

    def step(acc: Any, x: Any) -> tuple[Any, None]:
        return jax.tree_util.tree_map(jnp.add, acc, fn(x)), None

    total, _ = jax.lax.scan(step, init, xs)
    return total


_CACHE: dict[Any, Compiled] = {}


def _key(layout: Layout, loss: Loss) -> tuple[Any, ...]:
    """What the compiled functions depend on besides their arguments."""
    return (
        jax.tree_util.tree_structure(layout.template),
        tuple((e.key, e.size, e.offset, e.scale, e.lo, e.hi, e.shape) for e in layout.entries),
        tuple(layout.tied.items()),
        loss.name,
    )


def compiled(layout: Layout, loss: Loss) -> Compiled:
    """The (cached) :class:`Compiled` functions for this layout's structure and this loss."""
    key = _key(layout, loss)
    fns = _CACHE.get(key)
    if fns is None:
        if len(_CACHE) > 64:
            _CACHE.clear()
        fns = _CACHE[key] = Compiled(layout, loss)
    return fns
