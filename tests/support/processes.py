"""Separate processes for the tests that need them: the repository root (their working
directory and PYTHONPATH), a free local port, and a real Dask cluster (a scheduler and
workers started as their own processes, as on other machines)."""

from __future__ import annotations

import multiprocessing
import os
import random
import signal
import socket
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

ROOT = Path(__file__).resolve().parents[2]


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def child_env() -> dict[str, str]:
    """The environment of a child process: this checkout importable, one BLAS thread."""
    return os.environ | {"PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}


def ctrl_c_when(
    command: list[str], ready: Callable[[], bool], timeout_s: float = 240
) -> tuple[subprocess.Popen, str, str, float]:
    """Run `command` (Python's default SIGINT handling restored), send it Ctrl-C (SIGINT) once
    `ready()`, and return the process, its stdout and stderr, and how long after the signal
    it ended (s)."""
    proc = subprocess.Popen(
        command,
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        deadline = time.monotonic() + timeout_s
        while not ready():
            assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read() if proc.stderr else ""
            time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
        sent = time.monotonic()
        out, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    return proc, out, err, time.monotonic() - sent


def _wait_for_port(port: int, proc: subprocess.Popen, log: Path, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            return
        except OSError:
            assert time.monotonic() < deadline and proc.poll() is None, log.read_text()
            time.sleep(0.2)


@contextmanager
def dask_cluster(log: Path, n_workers: int = 2) -> Iterator[str]:
    """A scheduler and `n_workers` single-threaded workers on localhost, each its own
    process (their output in `log`); yields the scheduler address once every worker has
    joined, and stops them all afterwards."""
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = child_env()
    scheduler = [sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", str(port)]
    worker = [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1", "--nworkers", "1"]
    with open(log, "w") as out:
        procs = [subprocess.Popen([*scheduler, "--no-dashboard"], env=env, cwd=ROOT, stdout=out, stderr=out)]
        try:
            _wait_for_port(port, procs[0], log, 60)
            for _ in range(n_workers):
                procs.append(subprocess.Popen([*worker, "--no-dashboard"], env=env, cwd=ROOT, stdout=out, stderr=out))
            from dask.distributed import Client

            with Client(address, timeout="60s") as client:
                client.wait_for_workers(n_workers, timeout=120)
            yield address
        finally:
            for p in reversed(procs):
                p.terminate()
            for p in procs:
                try:
                    p.wait(20)
                except subprocess.TimeoutExpired:
                    p.kill()


def kill_at_random_moments(
    target: Callable[..., object], args: tuple, reference_s: float, seed: int, window: tuple[float, float]
) -> tuple[int, bool]:
    """Run `target(*args)` in a forked child up to five times, each killed with SIGKILL (no
    cleanup: a lock left behind, maybe a half-written temporary file) at a random moment
    of `window` × `reference_s` unless it finished first; (kills, whether one finished)."""
    ctx = multiprocessing.get_context("fork")
    rng = random.Random(seed)
    kills = 0
    for _ in range(5):
        child = ctx.Process(target=target, args=args)
        child.start()
        child.join(rng.uniform(*window) * reference_s)
        if child.exitcode is not None:
            assert child.exitcode == 0
            return kills, True
        child.kill()
        child.join(30)
        kills += 1
        time.sleep(0.05)
    return kills, False
