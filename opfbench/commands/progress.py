"""Progress over tasks on stderr: a tqdm bar (rate, ETA) on a terminal, one plain line per
task otherwise, nothing with `quiet`."""

from __future__ import annotations

import sys

from opfbench.study.engine import TaskOutput


class Progress:
    def __init__(self, total: int, done: int, quiet: bool = False):
        self.total, self.count, self.quiet = total, done, quiet
        self.bar = None
        if not quiet and sys.stderr.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, initial=done, unit="task", file=sys.stderr, dynamic_ncols=True, smoothing=0.1)
        elif not quiet and done:
            print(f"resuming: {done}/{total} tasks already done", file=sys.stderr, flush=True)

    def update(self, result: TaskOutput) -> None:
        self.count += 1
        if self.bar is not None:
            self.bar.set_postfix_str(result.task.label, refresh=False)
            self.bar.update(1)
        elif not self.quiet:
            print(f"[{self.count}/{self.total}] {result.task.label}  {result.wall_s:.1f} s", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
