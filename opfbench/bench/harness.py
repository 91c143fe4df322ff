"""Run one benchmark module in this process between two timings of a fixed reference
workload, and print its figures and the workload's time as one JSON object:

    python PATH/TO/harness.py NAME [the benchmark's options]

`calibration_ms` is the median of the two timings (each the best of CALIBRATION_REPEATS):
a peer measured in the same process as the benchmark, for the keys that have no peer of
their own (`opfbench.bench.record`). Run as a script by path, it imports of opfbench only
`opfbench.bench.NAME` and `opfbench.jsonio` — modules every checkout since the first
benchmarks has — so an older checkout's benchmarks run under it too (`python -m
opfbench.bench all --tree DIR` puts DIR first on PYTHONPATH).
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import sys
import time

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu
from threadpoolctl import threadpool_limits

from opfbench.jsonio import json_safe

CALIBRATION_REPEATS = 5


def _workload() -> float:
    """The reference work (single-threaded): small complex mat-muls, a sparse LU solve and
    a loop of Python calls — what the benchmarks' own code mixes. Returns a checksum."""
    rng = np.random.default_rng(0)
    z = rng.standard_normal((32, 32)) + 1j * rng.standard_normal((32, 32))
    x = rng.standard_normal((32, 1440)) + 1j * rng.standard_normal((32, 1440))
    total = 0.0
    for _ in range(20):
        x = z @ x
        x /= np.abs(x).max()
    n = 2000
    lap = sp.diags([-np.ones(n - 1), 2.5 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1], format="csc")
    lu = splu(lap)
    total += float(lu.solve(np.ones((n, 64))).sum())
    d: dict[int, float] = {}
    for i in range(50_000):
        d[i % 97] = d.get(i % 97, 0.0) + math.sqrt(i)
    return total + float(abs(x).sum()) + sum(d.values())


def calibration_ms() -> float:
    """Best CPU time (ms, `time.process_time`) of CALIBRATION_REPEATS runs of the reference
    workload (single-threaded: on a shared machine the time it ran, not the time it waited)."""
    best = math.inf
    with threadpool_limits(1):
        for _ in range(CALIBRATION_REPEATS):
            start = time.process_time()
            _workload()
            best = min(best, (time.process_time() - start) * 1e3)
    return best


def main(argv: list[str]) -> int:
    name, options = argv[0], argv[1:]
    module = importlib.import_module(f"opfbench.bench.{name}")
    before = calibration_ms()
    if hasattr(module, "add_arguments"):
        parser = argparse.ArgumentParser(prog=f"bench {name}")
        module.add_arguments(parser)
        figures = module.run(parser.parse_args(options))
    else:
        figures = module.run()
    after = calibration_ms()
    figures["calibration_ms"] = float(np.median([before, after]))
    figures["calibration_ms_runs"] = [before, after]
    print(json.dumps(json_safe(figures), allow_nan=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
