"""Vectorised 2-D Perlin (gradient) noise in numpy, seeded, evaluated at arbitrary points.

A 40-line implementation instead of a dependency: the PyPI ``noise`` package needs a C compiler and is
unmaintained, ``perlin-numpy`` only fills regular grids.
"""

from __future__ import annotations

import numpy as np


class Perlin2D:
    """Classic Perlin noise on a periodic lattice of ``period`` cells; values roughly in [-1, 1].

    ``frequency`` is lattice cells per metre, so features are ~1/frequency metres wide.
    """

    def __init__(self, rng: np.random.Generator, frequency: float = 4.0, period: int = 64):
        angles = rng.uniform(0.0, 2.0 * np.pi, size=(period, period))
        self.grad = np.stack([np.cos(angles), np.sin(angles)], axis=-1)
        self.offset = rng.uniform(0.0, period, size=2)
        self.frequency = frequency
        self.period = period

    def __call__(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64) * self.frequency + self.offset[0]
        y = np.asarray(y, dtype=np.float64) * self.frequency + self.offset[1]
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = x - x0, y - y0
        i0, j0 = x0.astype(np.int64) % self.period, y0.astype(np.int64) % self.period
        i1, j1 = (i0 + 1) % self.period, (j0 + 1) % self.period

        def dot(i, j, dx, dy):
            g = self.grad[i, j]
            return g[..., 0] * dx + g[..., 1] * dy

        n00, n10 = dot(i0, j0, fx, fy), dot(i1, j0, fx - 1, fy)
        n01, n11 = dot(i0, j1, fx, fy - 1), dot(i1, j1, fx - 1, fy - 1)
        u, v = _fade(fx), _fade(fy)
        nx0 = n00 + u * (n10 - n00)
        nx1 = n01 + u * (n11 - n01)
        return np.sqrt(2.0) * (nx0 + v * (nx1 - nx0))


def _fade(t: np.ndarray) -> np.ndarray:
    return t * t * t * (t * (t * 6 - 15) + 10)
