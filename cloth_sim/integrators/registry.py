"""The registry of time integrators: user-facing name -> stepper class (:func:`register`,
:func:`available`, :func:`get`); :mod:`cloth_sim.integrators` fills it and re-exports it."""

from __future__ import annotations

from ..kinds import INTEGRATORS
from .base import Integrator

_REGISTRY: dict[str, type[Integrator]] = {}


def register(cls: type[Integrator]) -> type[Integrator]:
    """Class decorator adding an integrator to the registry under ``cls.name``."""
    if cls.name in _REGISTRY:
        raise ValueError(f"integrator {cls.name!r} is registered twice")
    if cls.name not in INTEGRATORS:
        raise ValueError(
            f"integrator {cls.name!r} is not declared: add its name to "
            f"cloth_sim.kinds.INTEGRATORS (the schema's accepted values)"
        )
    _REGISTRY[cls.name] = cls
    return cls


def available() -> list[str]:
    """Names of every registered integrator, in the order :data:`cloth_sim.kinds.INTEGRATORS`
    declares them (whatever order their modules were imported in)."""
    return [name for name in INTEGRATORS if name in _REGISTRY]


def get(name: str) -> type[Integrator]:
    """The integrator class for ``name``; an unknown name raises ``ValueError`` listing the
    names."""
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise ValueError(
            f"unknown integrator {name!r}; expected one of: {', '.join(available())}"
        ) from None
