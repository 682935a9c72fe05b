"""cloth_sim: mass-spring cloth (Provot 1995, Choi & Ko 2002) with explicit and implicit integrators.

The core (this package minus ``cloth_sim.ros``) imports numpy, scipy and numba only.
"""

from . import integrators
from .model import ClothModel
from .simulator import SimulationDiverged, Simulator

__all__ = ["ClothModel", "Simulator", "SimulationDiverged", "integrators"]
__version__ = "0.1.0"
