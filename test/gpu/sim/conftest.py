"""Kernels that run: on a GPU, or on numba-cuda's simulator (``NUMBA_ENABLE_CUDASIM=1``, set
before numba is imported: ``make test-gpu`` sets it where no GPU is found)."""

import pytest

from cloth_sim import backends


def pytest_configure(config):
    why = backends.problem("cuda")
    if why is not None:
        pytest.exit(f"the CUDA kernels cannot run here: {why}", 4)
