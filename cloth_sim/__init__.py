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

# The large-cloth spring forces run in numba's OpenMP pool: its idle workers must sleep, not spin,
# or they take a core from the ROS executor (and from anything else on a 2-core machine) between
# steps. Read when the OpenMP runtime starts, so set before any parallel kernel runs.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

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
