"""Long sweeps (``@pytest.mark.slow``) are opt-in: ``--runslow`` or CNC_INTERP_SLOW=1."""

import os

import pytest


def pytest_addoption(parser):
    parser.addoption("--runslow", action="store_true", default=False,
                     help="also run tests marked slow (long sweeps)")


def pytest_collection_modifyitems(config, items):
    if config.getoption("--runslow") or os.environ.get("CNC_INTERP_SLOW") == "1":
        return
    skip = pytest.mark.skip(reason="slow sweep: run with --runslow or CNC_INTERP_SLOW=1")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)
