"""Simulated sample seen by the simulated camera: a ground-truth gonio model plus noise.

Like ophyd's simulated detectors, the reading is computed from where the motors *are* (the
joint angles read back from the servo emulator), not where they were told to go. The noise is
Gaussian with ``sigma = noise_rel * f + noise_abs`` and drawn from a generator seeded by
``(seed, configuration index)``, so the same configuration always gives the same reading — a
resumed run reproduces an uninterrupted one exactly.
"""

from __future__ import annotations

import time

import numpy as np

from gonio.rigs.config import RigConfig
from gonio.rigs.devices import Capture, Geometry


class SimulatedSampleCamera:
    """Camera backend ``kind = "sim-sample"`` (a :class:`gonio.rigs.devices.DirectCamera`):
    BRDF reading of the rig file's ``[sim.sample]``."""

    takes_raw = False

    def __init__(self, rig: RigConfig) -> None:
        from gonio.rigs.sim.truth import load_truth

        self.model = load_truth(rig.sim.sample, rig.source)
        self._f = None
        self.seed = rig.sim.seed
        self.noise_rel = rig.sim.noise_rel
        self.noise_abs = rig.sim.noise_abs
        self.capture_time_s = float(rig.camera.get("capture_time_s", 0.0))
        self.exposure_s = float(rig.camera.get("exposure_s", 0.01))
        c = self.model.n_channels
        self.channels = ("R", "G", "B") if c == 3 else tuple(f"c{i}" for i in range(c))

    def truth(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Ground-truth BRDF (1/sr), shape (..., C)."""
        import jax
        import jax.numpy as jnp

        from gonio.brdf import models

        if self._f is None:
            # jit at the device boundary: one compile, then each capture is one cheap call (an
            # analytic model; a table would be baked into the compiled code as a constant)
            is_model = isinstance(self.model, models.BRDFModel)
            self._f = jax.jit(self.model.f) if is_model else self.model.f
        f = self._f(jnp.asarray(wi, dtype=jnp.float64), jnp.asarray(wo, dtype=jnp.float64))
        return np.asarray(f, dtype=float)

    def capture(self, geometry: Geometry, exposure_s: float | None = None) -> Capture:
        if self.capture_time_s:
            time.sleep(self.capture_time_s)
        f = self.truth(geometry.wi, geometry.wo).reshape(-1)
        sigma = self.noise_rel * np.abs(f) + self.noise_abs
        rng = np.random.default_rng([self.seed, int(geometry.index)])
        value = f + sigma * rng.standard_normal(f.shape)
        return Capture(
            value=value,
            sigma=sigma,
            channels=self.channels[: len(value)],
            meta={"exposure_s": exposure_s or self.exposure_s},
        )

    def close(self) -> None:
        pass
