"""A seeded wind field for PyFlyt: a mean wind plus gusts.

PyFlyt 0.29 takes a wind model as ``Aviary(..., wind_type=<a WindFieldClass subclass>,
wind_options={...})`` and calls it with the simulation time and the positions of the drone's
drag bodies; the drag of the quadrotor's body then acts on the velocity relative to the air.

The gusts are a sum of ``N_MODES`` sinusoids per horizontal axis with random frequencies
(log-uniform within a factor e of ``1 / gust_period_s``), directions and phases, scaled so
that each horizontal component has standard deviation ``gust``. The field is uniform in space
and a pure function of time, drawn from its own seed: it does not depend on how often PyFlyt
samples it nor on the motor noise, so a scenario's wind is the same in every run.
"""

from __future__ import annotations

import numpy as np
from PyFlyt.core.abstractions import WindFieldClass

N_MODES = 8


class GustWind(WindFieldClass):
    """Mean wind plus gusts (m/s), uniform in space, seeded (see the module doc)."""

    def __init__(
        self,
        mean: tuple[float, float, float] = (0.0, 0.0, 0.0),
        gust: float = 0.0,
        gust_period_s: float = 4.0,
        seed: int = 0,
        np_random: np.random.Generator | None = None,
    ) -> None:
        super().__init__(np_random)
        rng = np.random.default_rng(seed)
        self.mean = np.asarray(mean, dtype=np.float64)
        # Amplitude per mode: N sinusoids of amplitude a with random phases have variance
        # N a^2 / 2, so a = gust * sqrt(2 / N) gives standard deviation ``gust`` per axis.
        self.amplitude = float(gust) * np.sqrt(2.0 / N_MODES)
        self.omega = 2 * np.pi / gust_period_s * np.exp(rng.uniform(-1.0, 1.0, (2, N_MODES)))
        self.phase = rng.uniform(0.0, 2 * np.pi, (2, N_MODES))

    def velocity(self, time: float) -> np.ndarray:
        """The wind velocity (3,) at ``time`` seconds."""
        w = self.mean.copy()
        if self.amplitude:
            w[:2] += self.amplitude * np.cos(self.omega * time + self.phase).sum(axis=1)
        return w

    def __call__(self, time: float, position: np.ndarray) -> np.ndarray:
        out = np.empty((len(position), 3))
        out[:] = self.velocity(time)
        return out


__all__ = ["GustWind"]
