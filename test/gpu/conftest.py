"""The CUDA backend's tests (``make test-gpu``; never part of ``make test``): they need numba-cuda
(``make gpu``). ``sim/`` runs the kernels on a GPU, or on numba-cuda's simulator where
``NUMBA_ENABLE_CUDASIM=1`` (how CI runs them, on tiny cloths); ``ptx/`` compiles every kernel to
PTX for an H100/H200 (sm_90), which needs NVVM but no GPU, and no simulator."""

import importlib.util

import pytest


def pytest_configure(config):
    if importlib.util.find_spec("numba_cuda") is None:
        pytest.exit("numba-cuda is not installed: `make gpu` installs requirements-gpu.txt", 4)
