"""Fixtures shared by the tests. Helper functions and data live in `tests/support/`
(imported as `from tests.support.<module> import <name>`); no test imports another test
module (`tests/test_test_layout.py` checks both)."""

from __future__ import annotations

from typing import Iterator

import pytest

from opfbench.io import load_network
from opfbench.network import Network
from tests.support.processes import dask_cluster as _dask_cluster


@pytest.fixture(scope="session")
def paper33() -> Network:
    """The shipped `paper33` feeder (read-only: `Network` arrays cannot be written)."""
    return load_network("paper33")


@pytest.fixture(scope="session")
def dask_cluster(tmp_path_factory) -> Iterator[str]:
    """The address of a real Dask cluster on localhost: a scheduler and two single-threaded
    workers, each its own process (log in a temporary `dask.log`), shared by the tests."""
    with _dask_cluster(tmp_path_factory.mktemp("dask") / "dask.log") as address:
        yield address


@pytest.fixture
def isolated_registry() -> Iterator[None]:
    """Plugins loaded inside the test are forgotten after it: the registry's entries and
    the loaded-plugin list are restored (every plugin registers into the one registry)."""
    from opfbench import plugins
    from opfbench.registry.catalog import specs
    from opfbench.registry.specs import MODELS, STRATEGIES

    specs()  # the built-ins loaded (on first need) before the registry is taken
    entries, models, before = dict(STRATEGIES), dict(MODELS), {p.ref for p in plugins.loaded()}
    yield
    for source in plugins.loaded():
        if source.ref not in before:
            plugins.unload(source.ref)
    STRATEGIES.clear()
    STRATEGIES.update(entries)
    MODELS.clear()
    MODELS.update(models)
