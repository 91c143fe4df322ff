"""Running tasks: in this process (`workers=1`), on a local Dask cluster of worker
processes (`workers=N`, one thread each) or on an existing Dask cluster (`scheduler`
address). Results come back to this process, which writes each finished task to the run
folder as it arrives — workers need no access to the folder.

Ctrl-C: CasADi/IPOPT swallows SIGINT while it solves, so in-process runs install a handler
that only sets a flag; the flag is checked after each task, and a task that was running
when the flag was set is discarded (its solve may have been cut short). With Dask the
solves run in other processes and the interrupt stops the wait at once; the local
cluster is shut down. Either way KeyboardInterrupt propagates after the finished tasks
are saved.
"""

from __future__ import annotations

import signal
from typing import Callable

from opfbench.study.tasks import TaskInput, TaskOutput, run_task

Save = Callable[[TaskOutput], None]


class _Interrupt:
    """SIGINT → a flag (a second Ctrl-C raises at once)."""

    def __init__(self):
        self.hit = False

    def __enter__(self) -> "_Interrupt":
        self.previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def _handle(self, signum, frame) -> None:
        if self.hit:
            raise KeyboardInterrupt
        self.hit = True

    def __exit__(self, *exc) -> None:
        signal.signal(signal.SIGINT, self.previous)


def run_in_process(inputs: list[TaskInput], save: Save) -> None:
    with _Interrupt() as stop:
        for inp in inputs:
            if stop.hit:
                break
            result = run_task(inp)
            if stop.hit:
                break
            save(result)
    if stop.hit:
        raise KeyboardInterrupt


def run_dask(inputs: list[TaskInput], save: Save, workers: int, scheduler: str | None) -> None:
    from dask.distributed import Client, LocalCluster, as_completed

    if scheduler:
        cluster, client = None, Client(scheduler, timeout="30s")
    else:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=40)
        client = Client(cluster)
    try:
        futures = [client.submit(run_task, inp, pure=False, priority=-i, key=f"task-{inp.task.id}-{i}")
                   for i, inp in enumerate(inputs)]
        for future in as_completed(futures):
            save(future.result())
            future.release()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def execute(inputs: list[TaskInput], save: Save, workers: int, scheduler: str | None) -> None:
    """Run `inputs`, calling `save` with each finished task (in completion order)."""
    if not inputs:
        return
    if scheduler is None and (workers <= 1 or len(inputs) == 1):
        run_in_process(inputs, save)
    else:
        run_dask(inputs, save, workers, scheduler)
