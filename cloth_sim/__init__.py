"""cloth_sim: mass-spring cloth (Provot 1995, Choi & Ko 2002) with explicit and implicit integrators.

The core (this package minus ``cloth_sim.ros``) imports numpy, scipy and numba only.

``cloth_sim.msg`` (the generated ``Stats`` message) is installed by rosidl into a package of the
same name: in one directory on a colcon install, in a separate prefix for the pip development
set-up, which ``extend_path`` below joins to this package.
"""

from pkgutil import extend_path

__path__ = extend_path(__path__, __name__)

from . import integrators
from .model import ClothModel
from .simulator import SimulationDiverged, Simulator

__all__ = ["ClothModel", "Simulator", "SimulationDiverged", "integrators"]
__version__ = "0.1.0"
