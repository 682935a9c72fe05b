"""The CUDA backend: cloth stepped on an NVIDIA GPU by numba-cuda (``requirements-gpu.txt``,
``make gpu``), behind :mod:`cloth_sim.backends`.

Importing this package imports numba-cuda (an optional dependency: a CPU-only install never
imports it; :func:`cloth_sim.backends.check_device` says what is missing). It runs on a GPU, or on
numba-cuda's simulator (``NUMBA_ENABLE_CUDASIM=1``: the kernels as Python, slow, for tests on tiny
cloths, which is how CI runs them).

* :mod:`~cloth_sim.cuda.layout`: the model's arrays as the kernels read them (host side, numpy).
* :mod:`~cloth_sim.cuda.kernels`: the per-vertex arithmetic and the kernels.
* :mod:`~cloth_sim.cuda.worlds`: :class:`~cloth_sim.cuda.worlds.CudaWorlds`, N cloths of one
  topology stepped together (one world is a :class:`cloth_sim.Simulator` on ``device="cuda"``).
"""

from __future__ import annotations

import numpy as np

# numba-cuda 0.30.4's compiler still refers to ``np.row_stack``, which numpy 2.4 deprecated and
# 2.5 removed (its lowering of array constructors fails inside the compiler without it); the one
# place this is handled, before numba.cuda compiles anything
if not hasattr(np, "row_stack"):
    np.row_stack = np.vstack

from numba import config, cuda  # noqa: E402  (after the compatibility line above)


def problem() -> str | None:
    """Why kernels cannot run here (``None`` when they can): no CUDA driver or device, unless
    numba-cuda's simulator is on."""
    if cuda.is_available():
        return None
    return (
        "no usable CUDA device: numba-cuda found no NVIDIA driver or GPU on this machine "
        "(NUMBA_ENABLE_CUDASIM=1 runs the kernels on numba-cuda's simulator, for tests)"
    )


def simulated() -> bool:
    """Whether the kernels run on numba-cuda's simulator (``NUMBA_ENABLE_CUDASIM=1``)."""
    return bool(config.ENABLE_CUDASIM)
