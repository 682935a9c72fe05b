"""A fabric in SI units: what the textile tests measure, independent of any discretisation."""

from __future__ import annotations

import math
from dataclasses import dataclass

#: gravity's magnitude in the textile tests' closed forms (bending length c = (G/(w·g))^(1/3))
G_ACCEL = 9.81


def _finite(name: str, value, lo: float = 0.0, strict: bool = True) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"material.{name}: expected a number, got {value!r}") from None
    ok = math.isfinite(v) and (v > lo if strict else v >= lo)
    if not ok:
        bound = f"> {lo:g}" if strict else f">= {lo:g}"
        raise ValueError(f"material.{name}: must be finite and {bound}, got {value!r}")
    return v


def _pair(name: str, value, strict: bool = True) -> tuple[float, float]:
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        value = (value, value)
    try:
        a, b = value
    except (TypeError, ValueError):
        raise ValueError(
            f"material.{name}: expected one number or a (warp, weft) pair, got {value!r}"
        ) from None
    return _finite(f"{name}[warp]", a, strict=strict), _finite(f"{name}[weft]", b, strict=strict)


@dataclass(frozen=True)
class Fabric:
    """A fabric's mechanics per unit area (the cloth's own frame: warp and weft).

    Attributes:
        density: areal density ``w``, kg/m².
        stretch: ``(warp, weft)`` tensile stiffness, N/m: force per width over strain in a strip
            test along that direction (free to narrow), ``E·t`` of the literature.
        shear: in-plane shear stiffness, N/m (``G₁₂·t``): shear force per length over the shear
            angle.
        bend: ``(warp, weft)`` flexural rigidity, N·m (moment per width over curvature: Peirce's
            ``G``; a cantilever strip cut along warp measures the warp value).
        poisson: the weft's contraction per warp strain (``ν₁₂``), dimensionless, in [0, 1).
        damping: stiffness-proportional (Rayleigh) damping time ``β``, s: each spring's damping is
            ``β·k``, the same at any resolution. 0: none.
        source: where the numbers come from.

    A negative, zero (``density``, ``stretch``) or non-finite value raises ``ValueError`` naming
    the field and the accepted range."""

    density: float
    stretch: tuple[float, float]
    shear: float
    bend: tuple[float, float]
    poisson: float = 0.0
    damping: float = 0.0
    source: str = ""

    def __post_init__(self):
        set_ = object.__setattr__
        set_(self, "density", _finite("density", self.density))
        set_(self, "stretch", _pair("stretch", self.stretch))
        set_(self, "shear", _finite("shear", self.shear, strict=False))
        set_(self, "bend", _pair("bend", self.bend, strict=False))
        p = _finite("poisson", self.poisson, strict=False)
        if p >= 1.0:
            raise ValueError(f"material.poisson: must lie in [0, 1), got {self.poisson!r}")
        set_(self, "poisson", p)
        set_(self, "damping", _finite("damping", self.damping, strict=False))
        if not isinstance(self.source, str):
            raise ValueError(f"material.source: expected a string, got {self.source!r}")

    # ------------------------------------------------------------------ closed forms
    def bending_length(self, direction: int = 0) -> float:
        """Peirce's bending length ``c = (G/(w·g))^(1/3)`` in m (``direction`` 0 warp, 1 weft):
        the cantilever test's strip meets the 41.5° line at an overhang of ``2c``."""
        return (self.bend[direction] / (self.density * G_ACCEL)) ** (1.0 / 3.0)

    def as_dict(self) -> dict:
        """The fields as plain numbers and lists (a scene's ``material:`` mapping)."""
        return {
            "density": self.density,
            "stretch": list(self.stretch),
            "shear": self.shear,
            "bend": list(self.bend),
            "poisson": self.poisson,
            "damping": self.damping,
        }

    @classmethod
    def from_mapping(cls, value: dict, where: str = "material") -> "Fabric":
        """A fabric from a mapping of the fields (a scene file's ``material:``); an unknown or a
        missing key raises ``ValueError`` naming it."""
        if not isinstance(value, dict):
            raise ValueError(f"{where}: expected a mapping of the fabric's fields, got {value!r}")
        fields = ("density", "stretch", "shear", "bend", "poisson", "damping", "source")
        unknown = sorted(set(map(str, value)) - set(fields))
        if unknown:
            raise ValueError(f"{where}: unknown keys {unknown}; expected {', '.join(fields)}")
        missing = [k for k in ("density", "stretch", "shear", "bend") if k not in value]
        if missing:
            raise ValueError(f"{where}: missing {', '.join(missing)}")
        try:
            return cls(**value)
        except ValueError as e:
            raise ValueError(f"{where}: {e}") from None

    def scaled(self, **factors) -> "Fabric":
        """A copy with fields multiplied: ``scaled(stretch=2, bend=0.5)`` (a fit's candidate)."""
        d = self.as_dict()
        for k, f in factors.items():
            if k not in d or k == "poisson":
                raise ValueError(f"material: cannot scale {k!r}")
            v = d[k]
            d[k] = [f * a for a in v] if isinstance(v, list) else f * v
        return Fabric(**d, source=self.source)
