"""cloth_sim: mass-spring cloth (Provot 1995, Choi & Ko 2002) with explicit and implicit integrators.

The core (this package minus ``cloth_sim.ros``, ``cloth_sim.bag`` and the benchmarks' front ends)
imports numpy, scipy, numba and yaml only. Its public names are imported when first used (PEP 562),
so ``import cloth_sim.ros`` can set up signal handling before the numerical libraries load.

``cloth_sim.msg`` (the generated ``Stats`` message) is installed by rosidl into a package of the
same name: in one directory on a colcon install, in a separate prefix for the pip development
set-up, which ``extend_path`` below joins to this package.
"""

import os
from pkgutil import extend_path

__path__ = extend_path(__path__, __name__)

# The spring forces of a cloth from ~48×48 up run in numba's OpenMP pool (GNU libgomp). Its idle
# workers must not spin for long, or they take a core from the ROS executor (and from anything else
# on a 2-core machine) between ticks; but put to sleep at once (OMP_WAIT_POLICY=PASSIVE) they must
# be woken for each of a step's two parallel regions, which cost what a 128×128 cloth gains. A
# bounded spin (10,000 rounds: ~0.1 ms of CPU per idle spell, measured, against 49 ms per 50 ms with
# ACTIVE) keeps them awake from one region and step to the next within a tick, then lets them sleep:
# the gather is then 1.6× the serial loop at 64×64 and 128×128 (with PASSIVE: 0.58× at 64×64,
# 1.08× at 128×128). A user's own OMP_WAIT_POLICY or GOMP_SPINCOUNT wins. Read when the
# OpenMP runtime starts, so set before any parallel kernel runs.
if "OMP_WAIT_POLICY" not in os.environ:
    os.environ.setdefault("GOMP_SPINCOUNT", "10000")

__all__ = ["ClothModel", "Simulator", "SimulationDiverged", "integrators"]
__version__ = "0.1.0"

_LAZY = {"ClothModel": ".model", "Simulator": ".simulator", "SimulationDiverged": ".simulator",
         "integrators": ".integrators"}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        module = importlib.import_module(_LAZY[name], __name__)
        value = module if name == "integrators" else getattr(module, name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_LAZY))
