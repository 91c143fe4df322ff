"""Cases in: `load_case(spec)` → `Case` (`opfbench.io.loading`), the case sources a spec may
name (`opfbench.io.sources`), specs (`opfbench.io.spec`). Importing the package is light
(the CLI names the formats in its help before anything loads): its names load on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from opfbench.io.case import Case, CaseSeries
    from opfbench.io.loading import NO_DER_NOTE, load_case, load_network
    from opfbench.io.spec import CaseSpec, parse_spec

__all__ = ["NO_DER_NOTE", "Case", "CaseSeries", "CaseSpec", "load_case", "load_network", "parse_spec"]
_HOME = {"Case": "case", "CaseSeries": "case", "CaseSpec": "spec", "parse_spec": "spec"}


def __getattr__(name: str) -> Any:
    if name not in __all__:
        raise AttributeError(f"module 'opfbench.io' has no attribute {name!r}")
    from importlib import import_module

    value = getattr(import_module(f"opfbench.io.{_HOME.get(name, 'loading')}"), name)
    globals()[name] = value
    return value
