"""The compile check: every kernel to PTX, which numba-cuda's simulator cannot do."""

import os

import pytest


def pytest_configure(config):
    if os.environ.get("NUMBA_ENABLE_CUDASIM", "0") not in ("", "0"):
        pytest.exit(
            "the PTX compile check needs NUMBA_ENABLE_CUDASIM unset (the simulator "
            "compiles nothing)",
            4,
        )
