"""Process-wide mutable state, in one place with one lifetime.

Every table and cache that outlives a call is created here (`PROCESS.table`) or declares
how it is emptied (`PROCESS.on_reset`): the registry's tables (built-in entries stay,
plugins' go), the loaded plugins, installed learned-rule parameters, the case cache, the
formulations' solve cache and per-thread solver objects. `PROCESS.reset()` returns the
process to the state of a fresh import — what a study run through the Python API does
when it ends (`PROCESS.scope()`), so a notebook's second study gets nothing from its first.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any


class ProcessState:
    """The named tables and reset hooks of this process (see the module docstring)."""

    def __init__(self) -> None:
        self._tables: dict[str, dict] = {}
        self._resets: dict[str, Callable[[], None]] = {}

    def table(self, name: str) -> dict[Any, Any]:
        """The process's table `name` (created empty on first use)."""
        return self._tables.setdefault(name, {})

    def on_reset(self, name: str, reset: Callable[[], None]) -> None:
        """Call `reset()` when the process state is reset (`name` says what it empties)."""
        self._resets[name] = reset

    def reset(self) -> None:
        """Empty every cache and forget every plugin, installed parameter and other entry
        a call left behind (the hooks run in registration order)."""
        for reset in list(self._resets.values()):
            reset()

    @contextmanager
    def scope(self) -> Iterator[None]:
        """Run a block whose state (plugins, fitted rules, caches) ends with it."""
        try:
            yield
        finally:
            self.reset()

    def names(self) -> tuple[str, ...]:
        """What the state holds: its tables and reset hooks, by name."""
        return tuple(dict.fromkeys([*self._tables, *self._resets]))


PROCESS = ProcessState()
