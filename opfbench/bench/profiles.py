"""A synthetic but smooth day used by the benchmarks (so they need no data files):
loads follow a two-peak daily shape, PV a clear-sky bell with cloud dips, wind an AR(1)
process. Values are per unit (load multiplier; DER output per unit of rating)."""

from __future__ import annotations

import numpy as np


def synthetic_day(n: int = 1440, n_der: int = 5, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(load_scale (n,), der_pu (n, n_der)) for one day split into n steps; the last DER
    follows the wind shape, the others the PV shape."""
    rng = np.random.default_rng(seed)
    hours = np.linspace(0, 24, n, endpoint=False)
    load = 0.55 + 0.25 * np.exp(-((hours - 8.5) / 2.0) ** 2) + 0.45 * np.exp(-((hours - 19.0) / 2.5) ** 2)
    bell = np.clip(np.sin(np.pi * (hours - 6.0) / 14.0), 0, None) ** 1.5
    clouds = 1 - 0.4 * np.clip(np.convolve(rng.random(n) < 0.02, np.ones(30), "same"), 0, 1)
    wind = np.empty(n)
    wind[0] = 0.5
    for i in range(1, n):
        wind[i] = wind[i - 1] + 0.02 * (0.5 - wind[i - 1]) + 0.02 * rng.standard_normal()
    der = np.repeat((bell * clouds)[:, None], n_der, axis=1)
    der[:, -1] = np.clip(wind, 0.0, 1.0)
    return load, der
