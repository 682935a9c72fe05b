"""One registry of time integrators: user-facing name -> stepper class.

>>> from cloth_sim import integrators
>>> integrators.available()[:3]
['explicit_euler', 'symplectic_euler', 'midpoint']
"""

from __future__ import annotations

from ..kinds import INTEGRATORS
from . import explicit, implicit, local_global, vbd, xpbd  # noqa: F401 (each registers its methods)
from .base import Integrator
from .registry import available, get, register

if tuple(available()) != INTEGRATORS:
    raise ImportError(
        f"the integrators registered, {available()}, are not those cloth_sim.kinds."
        f"INTEGRATORS declares: {INTEGRATORS}"
    )

__all__ = ["Integrator", "available", "get", "register"]
