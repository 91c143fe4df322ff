"""Running a family's tasks: in this process (one worker), on a local Dask cluster of
worker processes (`workers=N`, one thread each) or on an existing Dask cluster
(`scheduler` address, checked before any work). Results come back to this process, which
writes each finished task to the folder as it arrives — workers need no access to it.

Tasks of one affinity (`engine.Task.affinity`, e.g. a run's tasks of one case and chunk,
one per k) run in one process — in this process back to back, in their order; on Dask in
one worker, unless there are fewer such groups than workers —, so that they share the work
the process caches (the formulations' solves by data: sharing changes no digit). On Dask
each task is a job of its own whose result is saved as soon as it arrives (a group's next
task is pinned to the worker that ran the one before: `_Chains`), so a stop after one task
of a group finished never loses it; the groups start costliest first (`Task.cost`), so that
the run does not end with one worker idle while the other runs a long group.

Ctrl-C: CasADi/IPOPT installs its own SIGINT handler while it solves and swallows the
signal, so in-process work blocks SIGINT in the main thread and waits for it in a watcher
thread (`signal.sigwait`), which either stops the process at once (the caller's `on_stop`,
the CLI's: exit code 130 — every finished task is already on disk, each written
atomically, the running one is dropped) or, without one, lets the running task finish
and save and then stops the work with KeyboardInterrupt (a library's caller).
With Dask the tasks run in other processes, which never see the signal (the local
cluster's worker processes start with SIGINT blocked, so a terminal's Ctrl-C reaches this
process alone); here Ctrl-C only raises a flag the wait for results looks at every 50 ms,
so it stops the wait at once — the local cluster is shut down and KeyboardInterrupt
propagates from there, never from inside a library's callback.
"""

from __future__ import annotations

import collections
import contextlib
import logging
import os
import signal
import socket
import threading
import warnings
from typing import Any, Callable, Iterator

from opfbench.errors import InputError
from opfbench.timing import elapsed_ms, now

Save = Callable[[Any], None]

CONNECT_S = 10  # seconds to reach a scheduler
POLL_S = 0.05  # seconds between looks for finished tasks and Ctrl-C while a cluster works
LIVENESS_S = 1.0  # seconds between looks for the workers that tasks are pinned to, while results are awaited
#: SILENT_LOGS: the local cluster logs only what is critical. A task's error reaches this
#: process through its future; what the workers would log besides is noise here — e.g. a
#: worker still busy when Ctrl-C shuts the scheduler down logs a traceback ("Failed to
#: communicate with scheduler during heartbeat").
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


def cores() -> int:
    """The cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def worker_count(asked: int | None, tasks: int, scheduler: str | None, note: Callable[[str], None]) -> int:
    """Local workers for `tasks` tasks: `asked` (None: one per core), never more than the
    tasks (a note says so when more were asked); 1 with a scheduler (its workers run them)."""
    if scheduler is not None:
        return 1
    n = cores() if asked is None else asked
    if tasks and n > tasks:
        if asked is not None:
            note(f"note: {tasks} task(s) to run: {tasks} worker(s), not {asked}")
        n = tasks
    return max(n, 1)


def scheduler_endpoint(address: str) -> tuple[str, int]:
    """(host, port) of a Dask scheduler address (tcp:// or tls:// HOST:PORT; a bare
    HOST:PORT is tcp); InputError for anything else."""
    scheme, _, location = address.rpartition("://")
    host, _, port = location.rpartition(":")
    host = host.strip("[]")
    if (scheme or "tcp") not in ("tcp", "tls") or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise InputError(
            f"--scheduler {address!r} is not a Dask scheduler address; give tcp://HOST:PORT (e.g. tcp://10.0.0.5:8786)"
        )
    return host, int(port)


def check_scheduler(address: str) -> None:
    """InputError unless something answers at the scheduler `address` within CONNECT_S
    seconds (`scheduler_endpoint`)."""
    host, port = scheduler_endpoint(address)
    try:
        socket.create_connection((host, port), timeout=CONNECT_S).close()
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise InputError(f"--scheduler {address}: no Dask scheduler answers there ({reason})") from None


class _SigintWatcher:
    """Inside the block SIGINT is blocked in this (main) thread and a daemon thread waits
    for it (`signal.sigwait`) and calls `on_stop`, which must end the process. A SIGINT
    the kernel hands to another thread that does not block it (threads started before the
    block, e.g. BLAS's) runs Python's handler in the main thread: it passes the signal on
    to the watcher."""

    def __init__(self, on_stop: Callable[[], None]):
        self.on_stop, self.armed = on_stop, True

    def _wait(self) -> None:
        signal.sigwait({signal.SIGINT})
        if self.armed:
            self.on_stop()

    def _pass_on(self, signum: int, frame: object) -> None:
        if self.thread.ident is not None:
            signal.pthread_kill(self.thread.ident, signal.SIGINT)

    def __enter__(self) -> "_SigintWatcher":
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        self.thread = threading.Thread(target=self._wait, daemon=True, name="opfbench-sigint")
        self.thread.start()
        self.handler = signal.signal(signal.SIGINT, self._pass_on)
        return self

    def __exit__(self, *exc) -> None:
        self.armed = False
        signal.signal(signal.SIGINT, self.handler)
        if self.thread.ident is not None:  # started in __enter__
            signal.pthread_kill(self.thread.ident, signal.SIGINT)  # wakes the watcher, which ends
        self.thread.join(5)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def stop_on_ctrl_c(on_stop: Callable[[], None]) -> contextlib.AbstractContextManager:
    """Inside the block Ctrl-C calls `on_stop` (once) from a watcher thread, whatever the
    main thread is running (IPOPT swallows the signal); outside the main thread, nothing."""
    main = threading.current_thread() is threading.main_thread()
    return _SigintWatcher(on_stop) if main else contextlib.nullcontext()


@contextlib.contextmanager
def _sigint_blocked() -> Iterator[None]:
    """SIGINT blocked in this thread inside the block: threads and processes started here
    inherit the mask (a local cluster's event loop and its worker processes). The
    multiprocessing resource tracker is started first: starting it unblocks SIGINT in the
    thread that does (the cluster's event loop, else)."""
    from multiprocessing import resource_tracker

    resource_tracker.ensure_running()
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


Job = tuple[Any, Any]  # (task, its input for the runner)


def by_affinity(jobs: list[Job]) -> list[list[Job]]:
    """The jobs grouped by their task's affinity, groups in the order of their first job,
    jobs in their order (module docstring)."""
    groups: dict[str, list[Job]] = {}
    for task, job in jobs:
        groups.setdefault(task.affinity, []).append((task, job))
    return list(groups.values())


def costliest_first(groups: list[list[Job]]) -> list[list[Job]]:
    """The groups by their tasks' total `cost`, the costliest first (ties in their order):
    the last to start are short, so no worker idles long while another finishes."""
    return sorted(groups, key=lambda group: -sum(task.cost for task, _ in group))


def run_here(runner: Callable, job: Any) -> tuple[str, Any]:
    """(the address of the Dask worker running it, `runner(job)`): a group's next task is
    pinned to that worker (`run_dask`)."""
    from distributed import get_worker

    return get_worker().address, runner(job)


def run_in_process(jobs: list[tuple[Any, Any]], runner: Callable, save: Save, on_stop: Callable[[], None] | None) -> None:
    """Run the jobs here, one after another. Ctrl-C calls `on_stop` from a watcher thread
    once no task is being written (`on_stop` must end the process, e.g. with os._exit); with
    no `on_stop`, the running task finishes and is saved, then KeyboardInterrupt."""
    saving, pressed = threading.Lock(), threading.Event()

    def stop() -> None:
        with saving:
            if on_stop is not None:
                on_stop()
            pressed.set()

    with stop_on_ctrl_c(stop):
        for _, job in (job for group in by_affinity(jobs) for job in group):
            result = runner(job)
            with saving:
                save(result)
            if pressed.is_set():
                raise KeyboardInterrupt


@contextlib.contextmanager
def _ctrl_c_requests() -> Iterator[threading.Event]:
    """Inside the block Ctrl-C only sets the event it yields (the main thread's SIGINT
    handler), so it never lands as a KeyboardInterrupt inside some library's callback,
    where Python would print and ignore it; the caller checks the event where stopping is
    safe."""
    pressed = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        yield pressed
        return
    previous = signal.signal(signal.SIGINT, lambda signum, frame: pressed.set())
    try:
        yield pressed
    finally:
        signal.signal(signal.SIGINT, previous)


class _Chains:
    """The groups' tasks on Dask, each task its own job whose result is saved as it
    arrives. As many groups are under way as the cluster has worker threads, the next (in
    the given order) starting when one ends, so each worker runs a group's tasks back to
    back, never another group's task in between: a group's first task goes to the worker
    that is free; each next one, submitted when the one before finished, is pinned to the
    worker that ran it — a restriction, not a preference, so the group shares that
    process's caches. A task pinned to a worker that is gone (it died; a nanny restarts it
    at another address) is moved to any worker (the liveness check, every LIVENESS_S while
    such tasks wait)."""

    def __init__(self, client: Any, runner: Callable, groups: list[list[Job]]):
        from dask.distributed import as_completed

        self.client, self.runner = client, runner
        self.finished = as_completed()
        self.waiting = collections.deque(enumerate(groups))  # (order, group) not started yet
        self.started = 0  # groups under way
        self.later: dict[Any, tuple[int, list[Job]]] = {}  # future → (its group's priority, the group's next jobs)
        self.pinned: dict[Any, tuple[str, list[Job]]] = {}  # future → (its worker, its job and the group's next)
        self.moved = 0
        self.checked = now()
        self._start_groups()

    def _start_groups(self) -> None:
        """Start the next groups while fewer are under way than the cluster has threads."""
        threads = max(sum(self.client.nthreads().values()), 1)
        while self.waiting and self.started < threads:
            i, group = self.waiting.popleft()
            self._submit(group, -i, None)
            self.started += 1

    def _submit(self, jobs: list[Job], priority: int, worker: str | None) -> None:
        (task, job), *later = jobs
        where: dict[str, Any] = {} if worker is None else {"workers": [worker], "allow_other_workers": False}
        key = f"task-{task.id}" + (f"-moved{self.moved}" if self.moved else "")
        future = self.client.submit(run_here, self.runner, job, pure=False, priority=priority, key=key, **where)
        self.later[future] = (priority, later)
        if worker is not None:
            self.pinned[future] = (worker, jobs)
        self.finished.add(future)

    def running(self) -> bool:
        return bool(self.later or self.waiting)

    def collect(self, save: Save) -> bool:
        """Save the results that arrived (each group's next task, or the next group,
        submitted first); False when none had."""
        batch = self.finished.next_batch(block=False)
        for future in batch:
            if future not in self.later:  # cancelled: moved off a worker that is gone
                continue
            worker, result = future.result()
            priority, later = self.later.pop(future)
            self.pinned.pop(future, None)
            future.release()
            if later:
                self._submit(later, priority, worker)
            else:
                self.started -= 1
                self._start_groups()
            save(result)
        if not batch and self.pinned and elapsed_ms(self.checked) > LIVENESS_S * 1e3:
            self._move_orphans()
        return bool(batch)

    def _move_orphans(self) -> None:
        self.checked = now()
        alive = set(self.client.nthreads())
        for future, (worker, jobs) in list(self.pinned.items()):
            if worker not in alive and future.status == "pending":
                priority, _ = self.later.pop(future)
                del self.pinned[future]
                future.cancel()
                self.moved += 1
                self._submit(jobs, priority, None)


def _peak_rss_mb() -> float:
    """This process's peak resident memory (MiB; run in a worker)."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def run_dask(jobs: list[tuple[Any, Any]], runner: Callable, save: Save, workers: int, scheduler: str | None) -> float | None:
    """Run the jobs on Dask. Returns the largest peak resident memory (MiB) of the local
    cluster's worker processes, asked of them after the last result (None: no local
    cluster); the cluster then shuts down in the background, while the caller assembles
    its tables and writes its report (the process waits for it at its exit). On an error
    or Ctrl-C it is shut down before this returns."""
    import dask
    from dask.distributed import Client, LocalCluster

    with _ctrl_c_requests() as pressed:
        if scheduler:
            try:
                cluster, client = None, Client(scheduler, timeout=f"{CONNECT_S}s")
            except (OSError, TimeoutError) as exc:
                raise InputError(f"--scheduler {scheduler}: could not connect ({type(exc).__name__})") from None
        else:
            with warnings.catch_warnings(), dask.config.set(LOCAL_CLUSTER_CONFIG), _sigint_blocked():
                # its small HTTP server (health checks) moves off a busy port
                warnings.filterwarnings("ignore", message="Port .* is already in use")
                cluster = LocalCluster(
                    n_workers=workers,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=None,
                    silence_logs=logging.CRITICAL,  # SILENT_LOGS
                )
                client = Client(cluster)
        try:
            groups = by_affinity(jobs)
            if len(groups) < (workers if cluster is not None else sum(client.nthreads().values())):
                groups = [[job] for job in jobs]  # every worker gets work first
            chains = _Chains(client, runner, costliest_first(groups))
            while chains.running():
                if pressed.is_set():
                    raise KeyboardInterrupt
                if not chains.collect(save):
                    pressed.wait(POLL_S)
            peak = max(client.run(_peak_rss_mb).values()) if cluster is not None else None
        except BaseException:
            client.close()
            if cluster is not None:
                cluster.close()
            raise
    client.close()
    if cluster is not None:
        threading.Thread(target=cluster.close, name="local-cluster-close").start()
    return peak


def execute(
    jobs: list[tuple[Any, Any]],
    runner: Callable,
    save: Save,
    workers: int,
    scheduler: str | None,
    on_stop: Callable[[], None] | None,
) -> float | None:
    """Run `runner` on each (task, input) of `jobs`, calling `save` with each result (in
    completion order); Ctrl-C in the in-process path: `on_stop` ends the process, or
    KeyboardInterrupt after the running task (`run_in_process`). Returns the local worker
    processes' peak memory (`run_dask`; None: none ran)."""
    if not jobs:  # every task kept from before: no cluster to start or reach
        return None
    if scheduler is None and workers <= 1:
        run_in_process(jobs, runner, save, on_stop)
        return None
    return run_dask(jobs, runner, save, workers, scheduler)
