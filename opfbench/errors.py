"""Typed errors. Every user-facing failure is one of these, with a message that names
what is wrong (file, matrix, row, column, value)."""


class OpfbenchError(Exception):
    """Base class of all errors opfbench raises on purpose."""


class CaseFormatError(OpfbenchError):
    """A case file is malformed: the message names file, matrix, row and the problem."""


class NetworkError(OpfbenchError):
    """A network is inconsistent (islanded buses, unknown bus, no slack, ...)."""


class InputError(OpfbenchError, ValueError):
    """An argument is outside its domain (k outside [0, 1], negative P, NaN in a profile, ...)."""


class DataError(OpfbenchError):
    """A data file or series is unusable (gaps left after cleaning, non-monotonic time, ...)."""


class Stopped(KeyboardInterrupt):
    """Ctrl-C, after the work done so far is saved; the message says what was kept (the
    CLI prints it on one line and exits with 130)."""
