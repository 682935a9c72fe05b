"""cloth_sim: mass-spring cloth (Provot 1995, Choi & Ko 2002) with explicit and implicit
integrators.

The core (this package minus ``cloth_sim.ros``, ``cloth_sim.bag`` and the benchmarks' front ends)
imports numpy, scipy, numba and yaml only. Its public names are imported when first used (PEP 562),
so ``import cloth_sim.ros`` can set up signal handling before the numerical libraries load.

``cloth_sim.msg`` (the generated ``Stats`` message) is installed by rosidl into a package of the
same name: in one directory on a colcon install, in a separate prefix for the pip development
set-up, which ``extend_path`` below joins to this package.
"""

import os
import sys
from pkgutil import extend_path

__path__ = extend_path(__path__, __name__)

# numba's threading layer: fork-safe. Its default on Linux is GNU OpenMP, and a process that forked
# after a parallel kernel ran (Gymnasium's async vector envs, multiprocessing's fork pools, data
# loaders) had its children killed ("fork() called from a process already using GNU OpenMP").
# "forksafe" takes Intel TBB (the ``tbb`` wheel, pinned in requirements.txt: as fast as OpenMP
# here, docs/BENCHMARKS.md) and falls back to numba's own workqueue where TBB cannot be loaded. A
# user's own NUMBA_THREADING_LAYER wins. Read when the first parallel kernel loads: set before
# that, and inherited by the processes this one starts (Ray's workers, a vector env's workers).
os.environ.setdefault("NUMBA_THREADING_LAYER", "forksafe")
if "numba" in sys.modules and sys.modules["numba"].config.THREADING_LAYER == "default":
    # numba was imported first (its configuration read the environment then): tell it directly
    sys.modules["numba"].config.THREADING_LAYER = os.environ["NUMBA_THREADING_LAYER"]

# For a user who chooses OpenMP (NUMBA_THREADING_LAYER=omp): its idle workers must not spin for
# long, or they take a core from the ROS executor between ticks; put to sleep at once
# (OMP_WAIT_POLICY= PASSIVE) they must be woken for each of a step's parallel regions. A bounded
# spin (10,000 rounds) keeps them awake within a tick, then lets them sleep. A user's
# OMP_WAIT_POLICY or GOMP_SPINCOUNT wins. Read when the OpenMP runtime starts.
if "OMP_WAIT_POLICY" not in os.environ:
    os.environ.setdefault("GOMP_SPINCOUNT", "10000")

# OpenBLAS's workers spin for a while after each call it runs on them, on the cores numba's
# kernels need: a dot product of 16,384 masses in the energy balance slowed the node's next vbd
# step by 40 %, and in the Warp benchmark's process (the other methods' bursts between ours)
# symplectic Euler's 128×128 step took 0.78 ms instead of 0.41 (docs/BENCHMARKS.md §11). The
# package's BLAS calls are small; they run on the calling thread. A user's OPENBLAS_NUM_THREADS
# wins. Read when numpy (or scipy's own OpenBLAS) loads: import cloth_sim first.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

__all__ = [
    "BatchSimulator",
    "ClothModel",
    "Simulator",
    "SimulationDiverged",
    "colliders",
    "integrators",
]
__version__ = "0.1.0"

_LAZY = {
    "BatchSimulator": ".batch",
    "ClothModel": ".model",
    "Simulator": ".simulator",
    "SimulationDiverged": ".simulator",
    "colliders": ".contact.colliders",
    "integrators": ".integrators",
}
_MODULES = ("colliders", "integrators")  # names that are modules, not a module's attribute


def __getattr__(name):
    if name in _LAZY:
        import importlib

        module = importlib.import_module(_LAZY[name], __name__)
        value = module if name in _MODULES else getattr(module, name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_LAZY))
