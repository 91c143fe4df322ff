"""How a study speaks on the terminal (`study.engine.Reporter`): notes on stderr, progress
over tasks — a tqdm bar (rate, ETA) on a terminal, one plain line per task otherwise,
nothing with `--quiet` — and Ctrl-C while the work runs in this process: one line, and
the process ends at once with exit code 130 (IPOPT swallows the signal; every finished
task is on disk)."""

from __future__ import annotations

import os
import sys
from typing import NoReturn

from opfbench.study.engine import Reporter, TaskOutput

STOPPED = 130  # exit code after Ctrl-C (128 + SIGINT)


class Progress:
    def __init__(self, total: int, done: int):
        self.total, self.count = total, done
        self.bar = None
        if sys.stderr.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, initial=done, unit="task", file=sys.stderr, dynamic_ncols=True, smoothing=0.1)
        elif done:
            print(f"resuming: {done}/{total} tasks already done", file=sys.stderr, flush=True)

    def update(self, result: TaskOutput) -> None:
        self.count += 1
        if self.bar is not None:
            self.bar.set_postfix_str(result.task.label, refresh=False)
            self.bar.update(1)
        else:
            print(f"[{self.count}/{self.total}] {result.task.label}  {result.wall_s:.1f} s", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def stop_now(message: str) -> NoReturn:
    say(message)
    os._exit(STOPPED)


def console(quiet: bool = False) -> Reporter:
    """The terminal's reporter: notes always, progress unless `quiet`, Ctrl-C at once."""
    return Reporter(note=say, progress=None if quiet else Progress, hard_stop=stop_now)
