"""Helpers shared by the tests (not tests themselves): always imported as
`from tests.support.<module> import <name>`; fixtures live in `tests/conftest.py`."""
