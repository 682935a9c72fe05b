"""The physics of the cloth: spring and external forces (:mod:`.forces`), the stability analysis of
a material and step (:mod:`.stability`), triangle meshes and their springs (:mod:`.mesh`), a
material's bending (:mod:`.bending`) and the energy balance that tells a chattering run from a
physical one (:mod:`.energy_balance`).

What users call: ``read_mesh`` (a garment's triangles from a file), ``Bending``, ``EnergyBalance``
and the stability analysis (``analysis_for``)."""

from .bending import Bending
from .energy_balance import EnergyBalance
from .mesh import read_mesh
from .stability import analysis_for

__all__ = ["Bending", "EnergyBalance", "analysis_for", "read_mesh"]
