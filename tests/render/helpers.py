"""Shared helpers for the renderer tests: closed-form pixel geometry, seed statistics and the
``gonio`` command line."""

from __future__ import annotations

import contextlib
import io
import subprocess
import sys

import numpy as np

from gonio.render import render_sphere


def ortho_normals(n: int) -> tuple[np.ndarray, np.ndarray]:
    """World normals (n, n, 3) of the orthographic pixel centres and the hit mask (n, n).

    Computed independently of gonio.render.scene from the scene convention (image covers
    [-1, 1]^2, x right, y up, row 0 at the top).
    """
    x = (np.arange(n) + 0.5) / n * 2 - 1
    y = 1 - (np.arange(n) + 0.5) / n * 2
    xx, yy = np.meshgrid(x, y)
    r2 = xx**2 + yy**2
    hit = r2 < 1
    zz = np.sqrt(np.maximum(0.0, 1 - r2))
    return np.stack([xx, yy, zz], -1), hit


def seed_stack(material, lights, k: int, **kw) -> np.ndarray:
    """``k`` renders with seeds 0..k-1 stacked: (k, H, W, C) float64."""
    return np.stack(
        [render_sphere(material, lights, seed=s, **kw).astype(np.float64) for s in range(k)]
    )


def block_means(imgs: np.ndarray, block: int) -> np.ndarray:
    """Average (..., H, W, C) over block x block pixel squares -> (..., H/b, W/b, C)."""
    *lead, h, w, c = imgs.shape
    x = imgs.reshape(*lead, h // block, block, w // block, block, c)
    return x.mean(axis=(-4, -2))


def z_scores(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """z of the difference of two seed stacks' means, per element, from the seed spread.

    Each seed is an independent render, so the standard error of a mean over k seeds is the
    sample standard deviation over seeds / sqrt(k).
    """
    ka, kb = a.shape[0], b.shape[0]
    se2 = a.var(axis=0, ddof=1) / ka + b.var(axis=0, ddof=1) / kb
    d = a.mean(axis=0) - b.mean(axis=0)
    return d / np.sqrt(np.maximum(se2, 1e-30))


def gonio_cli(*args, real: bool = False) -> subprocess.CompletedProcess:
    """``gonio ARGS``: exit status, stdout and stderr, as a ``CompletedProcess``.

    By default the command runs in this process (:func:`gonio.cli.main`, stdout and stderr
    captured): a ``python -m gonio`` child pays ``import jax`` and compiles every render kernel
    again (5-30 s a call on this suite's machine), while in-process calls share the compiled
    kernels. ``real=True`` runs the real entry point, ``python -m gonio``, in a child process.
    Either way no traceback may reach stderr (in-process, an escaped exception fails the test).
    """
    argv = [str(a) for a in args]
    if real:
        out = subprocess.run(
            [sys.executable, "-m", "gonio", *argv],
            capture_output=True,
            text=True,
            timeout=600,
        )
    else:
        from gonio.cli import main

        stdout, stderr = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
            rc = main(argv)
        out = subprocess.CompletedProcess(argv, rc, stdout.getvalue(), stderr.getvalue())
    assert "Traceback" not in out.stderr, out.stderr
    return out
