"""Fabrics in SI units and their mapping onto a model: a layer below the model.

``materials.names()`` lists the library, ``materials.get(name)`` gives a :class:`Fabric`;
:mod:`.discretize` maps a fabric onto a grid or a mesh (what ``ClothModel.grid(size=…,
material=…)`` uses). The textile standard tests (:mod:`cloth_sim.textile`) and the fit to a
recording (:mod:`cloth_sim.fit`) run the simulator, at the edge.
"""

from __future__ import annotations

from .fabric import Fabric
from .library import LIBRARY

__all__ = ["Fabric", "names", "get", "resolve"]


def names() -> list[str]:
    """The library's fabric names (measured names and the generic aliases), sorted."""
    return sorted(LIBRARY)


def get(name: str) -> Fabric:
    """The library fabric ``name``; an unknown name raises ``ValueError`` listing the known."""
    try:
        return LIBRARY[name]
    except (KeyError, TypeError):
        raise ValueError(
            f"material: unknown fabric {name!r}; the library has {', '.join(names())}"
        ) from None


def resolve(material) -> Fabric:
    """A :class:`Fabric` from a fabric, a library name or a mapping of the fields."""
    if isinstance(material, Fabric):
        return material
    if isinstance(material, str):
        return get(material)
    if isinstance(material, dict):
        return Fabric.from_mapping(material)
    raise ValueError(
        f"material: expected a library name, a mapping of the fabric's fields or a Fabric, "
        f"got {material!r}"
    )
