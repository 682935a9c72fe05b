"""numba's thread pool, started before a compiled kernel that needs it runs.

A kernel compiled without ``parallel=True`` that calls one compiled with it (``runge_kutta_fused``
calling the springs' gather, the strain projection's solve calling its search for the springs over
their bound, Baraff–Witkin's CG calling its products) crashes when it is loaded from numba's cache
into a process where no parallel kernel has run yet: the cached caller does not start the pool its
callee's parallel region runs on (numba/numba#8578, open in numba 0.68). A cold cache hides it
(compiling starts the pool) and so does any parallel kernel run first, which is why it surfaced
only in fresh processes on a warm cache: RK4's and explicit Euler's first step on the hanging
scene's 32×32 cloth was a segmentation fault every time. The objects that call such kernels start
the pool when they are built (:func:`start_pool`, idempotent).
"""

from __future__ import annotations

import numba


def start_pool() -> None:
    """Start numba's parallel thread pool in this process if it is not yet running (it reads the
    threading layer ``cloth_sim/__init__.py`` chose); ~0.5 µs once it runs."""
    numba.get_num_threads()
