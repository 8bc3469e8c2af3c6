"""Fixtures of the property-based suite."""

import pytest

from fdia_env import scenarios


@pytest.fixture(scope="session", autouse=True)
def built_presets():
    """Build every preset once before the properties run.

    The grid presets run pandapower on their first ``scenarios.get`` (seconds, more on a loaded
    machine) and are cached after; building them here keeps that one-off cost out of the
    per-example deadline and the hard time bound, which measure the call under test.
    """
    for name in scenarios.names():
        try:
            scenarios.get(name)
        except ImportError:  # the [grid] extra is not installed: those examples say so
            pass
