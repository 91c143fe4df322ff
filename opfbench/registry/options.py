"""Typed strategy options: what a label's `key=value` may say, how it is parsed, checked,
coerced from a Python value and written back exactly (the canonical label).

An option's type is its default's: bool (true/false), int, float (a decimal number), str
(one of `choices`, or free text) or a tuple of floats (written `0.9/1.0/1.1`). Light to
import (numpy only): every module that declares a strategy uses it.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from opfbench.errors import InputError
from opfbench.exact import number_text

_DECIMAL = re.compile(r"^[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?$", re.ASCII)
OptionValue = bool | int | float | str | tuple[float, ...]


@dataclass(frozen=True)
class Option:
    """A typed option. Its type is its default's: bool (true/false), int, float (a decimal
    number), str (one of `choices`) or a tuple of floats (written `0.9/1.0/1.1`);
    `check(value)` returns a problem (text) or None; `setting` names the run-level setting
    that supplies the default where a label does not set the option."""

    name: str
    default: OptionValue
    help: str
    choices: tuple[str, ...] = ()
    check: Callable[[OptionValue], str | None] | None = None
    setting: str | None = None

    @property
    def type_name(self) -> str:
        if isinstance(self.default, bool):
            return "bool"
        if isinstance(self.default, tuple):
            return "numbers"
        return {int: "int", float: "number", str: "choice" if self.choices else "text"}[type(self.default)]

    def parse(self, text: str) -> OptionValue:
        """The value written `text` in a label; InputError (without the context) otherwise."""
        kind = self.type_name
        if kind == "bool":
            if text.lower() not in ("true", "false"):
                raise InputError(f"{text!r} is not true or false")
            return text.lower() == "true"
        if kind == "int":
            if not re.fullmatch(r"[+-]?\d+", text):
                raise InputError(f"{text!r} is not a whole number")
            return int(text)
        if kind == "number":
            return _decimal(text)
        if kind == "numbers":
            return tuple(_decimal(part) for part in text.split("/")) if text else ()
        return text

    def coerce(self, value: object) -> OptionValue:
        """`value` as this option's type (an int for a float option is a float); InputError
        for another type (a text 'false' is no False)."""
        kind = self.type_name
        if isinstance(value, (bool, np.bool_)):
            if kind == "bool":
                return bool(value)
        elif kind == "int" and isinstance(value, (int, np.integer)):
            return int(value)
        elif kind == "number" and isinstance(value, (int, float, np.integer, np.floating)):
            return float(value)
        elif kind == "numbers" and isinstance(value, (tuple, list)) and all(_is_number(v) for v in value):
            return tuple(float(v) for v in value)
        elif kind in ("choice", "text") and isinstance(value, str):
            return value
        raise InputError(f"{value!r} is not a {kind} like its default {self.format(self.default)!r}")

    def validate(self, value: OptionValue) -> None:
        """InputError (without the context) unless `value` is allowed."""
        if isinstance(value, float) and not math.isfinite(value):
            raise InputError(f"{value} is not finite")
        if isinstance(value, tuple) and not all(math.isfinite(v) for v in value):
            raise InputError(f"{self.format(value)} has a value that is not finite")
        if self.choices and value not in self.choices:
            raise InputError(f"{value!r} is not one of {', '.join(self.choices)}")
        try:
            problem = self.check(value) if self.check is not None else None
        except (Exception, SystemExit) as exc:  # a plugin's check with a bug of its own: named, never a traceback
            raise InputError(f"its check failed on {self.format(value)} ({type(exc).__name__}: {exc})") from None
        if problem:
            raise InputError(str(problem))

    def format(self, value: OptionValue) -> str:
        """`value` as written in a canonical label (numbers exactly: repr, no trailing .0)."""
        if isinstance(value, bool):
            return "true" if value else "false"
        if isinstance(value, float):
            return number_text(value)
        if isinstance(value, tuple):
            return "/".join(number_text(v) for v in value)
        return str(value)

    def describe(self) -> dict:
        """The option as `opfbench strategies --json` lists it."""
        out: dict[str, object] = {
            "name": self.name,
            "type": self.type_name,
            "default": self.format(self.default),
            "help": self.help,
        }
        if self.choices:
            out["allowed"] = list(self.choices)
        if self.setting:
            out["default_from"] = self.setting
        return out


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def _decimal(text: str) -> float:
    if not _DECIMAL.match(text):
        raise InputError(f"{text!r} is not a decimal number")
    value = float(text)
    if not math.isfinite(value):
        raise InputError(f"{text!r} is not finite")
    return value
