"""Running tasks: in this process (`workers=1`), on a local Dask cluster of worker
processes (`workers=N`, one thread each) or on an existing Dask cluster (`scheduler`
address). Results come back to this process, which writes each finished task to the run
folder as it arrives — workers need no access to the folder.

Ctrl-C: CasADi/IPOPT installs its own SIGINT handler while it solves and swallows the
signal, so in-process runs block SIGINT in the main thread and wait for it in a watcher
thread (`signal.sigwait`), which stops the process at once (exit code 130) — every
finished task is already on disk (each written atomically), the running one is dropped.
With Dask the solves run in other processes and the interrupt stops the wait at once; the
local cluster is shut down and KeyboardInterrupt propagates.
"""

from __future__ import annotations

import contextlib
import signal
import threading
import warnings
from typing import Callable

from opfbench.study.tasks import TaskInput, TaskOutput, run_task

Save = Callable[[TaskOutput], None]


STOPPED = 130  # exit code after Ctrl-C (128 + SIGINT)
#: The local cluster's workers:
#: - with glibc's default heap trimming: Dask's MALLOC_TRIM_THRESHOLD_=65536 (it returns
#:   freed memory to the OS at once) made the tasks slower than in this process; the
#:   single-threaded BLAS settings are kept;
#: - without the statistical profiler (it samples the task thread's stack every 10 ms),
#:   with slower event-loop ticks and system monitor (20 ms and 0.5 s by default), which
#:   otherwise take time from the tasks (`python -m opfbench.bench run` measures a run).
LOCAL_CLUSTER_CONFIG = {
    "distributed.nanny.pre-spawn-environ": {"OMP_NUM_THREADS": 1, "MKL_NUM_THREADS": 1, "OPENBLAS_NUM_THREADS": 1},
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
}


class _SigintWatcher:
    """Inside the block SIGINT is blocked in this (main) thread and a daemon thread waits
    for it (`signal.sigwait`) and calls `on_stop`, which must end the process."""

    def __init__(self, on_stop: Callable[[], None]):
        self.on_stop, self.armed = on_stop, True

    def _wait(self) -> None:
        signal.sigwait({signal.SIGINT})
        if self.armed:
            self.on_stop()

    def __enter__(self) -> "_SigintWatcher":
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        self.thread = threading.Thread(target=self._wait, daemon=True, name="opfbench-sigint")
        self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.armed = False
        if self.thread.ident is not None:  # started in __enter__
            signal.pthread_kill(self.thread.ident, signal.SIGINT)  # wakes the watcher, which ends
        self.thread.join(5)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def run_in_process(inputs: list[TaskInput], save: Save, on_stop: Callable[[], None]) -> None:
    """Run the tasks here, one after another; Ctrl-C calls `on_stop` from a watcher thread
    (`on_stop` must end the process, e.g. with os._exit) once no task is being written."""
    saving = threading.Lock()

    def stop() -> None:
        with saving:
            on_stop()

    main = threading.current_thread() is threading.main_thread()
    with _SigintWatcher(stop) if main else contextlib.nullcontext():
        for inp in inputs:
            result = run_task(inp)
            with saving:
                save(result)


def _done() -> None:
    """Nothing left to wait for."""


def run_dask(inputs: list[TaskInput], save: Save, workers: int, scheduler: str | None) -> Callable[[], None]:
    """Run `inputs` on Dask. Returns a function that waits until the local cluster (if one
    was started) has shut down: it shuts down in the background after the last result,
    while the caller assembles the tables; on an error or Ctrl-C it is shut
    down before this returns."""
    import dask
    from dask.distributed import Client, LocalCluster, as_completed

    if scheduler:
        cluster, client = None, Client(scheduler, timeout="30s")
    else:
        with warnings.catch_warnings(), dask.config.set(LOCAL_CLUSTER_CONFIG):
            # its small HTTP server (health checks) moves off a busy port
            warnings.filterwarnings("ignore", message="Port .* is already in use")
            cluster = LocalCluster(
                n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None, silence_logs=40
            )
        client = Client(cluster)
    try:
        futures = [
            client.submit(run_task, inp, pure=False, priority=-i, key=f"task-{inp.task.id}-{i}") for i, inp in enumerate(inputs)
        ]
        for future in as_completed(futures):
            save(future.result())
            future.release()
    except BaseException:
        client.close()
        if cluster is not None:
            cluster.close()
        raise
    client.close()
    if cluster is None:
        return _done
    closing = threading.Thread(target=cluster.close, name="local-cluster-close")
    closing.start()
    return closing.join


def execute(
    inputs: list[TaskInput], save: Save, workers: int, scheduler: str | None, on_stop: Callable[[], None]
) -> Callable[[], None]:
    """Run `inputs`, calling `save` with each finished task (in completion order);
    `on_stop` ends the process on Ctrl-C in the in-process path. Returns a function that
    waits until every local worker process has exited (`run_dask`)."""
    if not inputs:  # every task kept from before: no cluster to start or reach
        return _done
    if scheduler is None and (workers <= 1 or len(inputs) == 1):
        run_in_process(inputs, save, on_stop)
        return _done
    return run_dask(inputs, save, workers, scheduler)
