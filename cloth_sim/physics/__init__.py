"""The physics of the cloth: spring and external forces (:mod:`.forces`, their kernels
:mod:`.force_kernels`), the stability analysis of a material and step (:mod:`.stability`),
triangle meshes and their springs (:mod:`.mesh`), a material's bending (:mod:`.bending`) and the
energy balance that tells a chattering run from a physical one (:mod:`.energy_balance`).

What users call, imported when first used: ``read_mesh`` (a garment's triangles from a file),
``Bending``, ``EnergyBalance`` and the stability analysis (``analysis_for``). :mod:`.mesh` and
:mod:`.bending` lie below the model (it builds from them); the others above it."""

from ..lazy import exports

_NAMES = {
    "Bending": ".bending",
    "EnergyBalance": ".energy_balance",
    "analysis_for": ".stability",
    "read_mesh": ".mesh",
}
__all__ = sorted(_NAMES)
__getattr__, __dir__ = exports(__name__, _NAMES)
