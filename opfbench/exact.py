"""One exact text for every number an option or a spec carries: the shortest decimal that
reads back to the same float (Python's repr), without a trailing `.0` — so a value is
never rounded on its way into a label, a case spec or a model (`0.91234567` stays that,
not `0.912346`)."""

from __future__ import annotations


def number_text(value: float) -> str:
    """`value` as the shortest text that reads back to exactly it (`1.0` → `1`)."""
    text = repr(float(value))
    return text[:-2] if text.endswith(".0") else text
