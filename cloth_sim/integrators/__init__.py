"""One registry of time integrators: user-facing name -> stepper class.

>>> from cloth_sim import integrators
>>> integrators.available()[:3]
['explicit_euler', 'symplectic_euler', 'midpoint']
"""

from __future__ import annotations

from .base import Integrator

_REGISTRY: dict[str, type[Integrator]] = {}


def register(cls: type[Integrator]) -> type[Integrator]:
    """Class decorator adding an integrator to the registry under ``cls.name``."""
    if cls.name in _REGISTRY:
        raise ValueError(f"integrator {cls.name!r} is registered twice")
    _REGISTRY[cls.name] = cls
    return cls


def available() -> list[str]:
    """Names of every registered integrator, in registration order."""
    return list(_REGISTRY)


def get(name: str) -> type[Integrator]:
    """The integrator class for ``name``; an unknown name raises ``ValueError`` listing the names."""
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown integrator {name!r}; expected one of: "
                         f"{', '.join(available())}") from None


from . import explicit, implicit, local_global, xpbd  # noqa: E402,F401  (registers the methods, in this order)
from . import vbd  # noqa: E402,F401  (after xpbd: the registry lists the methods in the order they came)

__all__ = ["Integrator", "available", "get", "register"]
