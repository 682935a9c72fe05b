"""``vbd``'s options (``integrator_options`` of ``Simulator(..., integrator="vbd")``), each with
its default and its check in one place: :class:`VBDOptions`. The integrator (:mod:`.vbd`) reads
them from here; what each one does is said there."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

#: the relative residual a step iterates down to by default (:mod:`.vbd_residual`: the force
#: imbalance over the weight, RMS over the free vertices)
TOLERANCE = 1e-2
#: iterations between two measures of the residual
CHECK_EVERY = 5
#: the implicit step a substep solves: ``bdf2`` (second order) or backward ``euler``
SCHEMES = ("bdf2", "euler")
#: the thicknesses a collider within reach of the cloth may travel in a substep where the cloth
#: self-collides (``collider_share="auto"``): a faster one cuts the step into substeps
#: (:meth:`~cloth_sim.contact.colliders.Contacts.travels`). Self-contact's bounds are what hold
#: the cloth back: each layer moves at most γ of its gap to the next between two searches, so a
#: fold a link pushes follows it slower than the link goes. robot_sweep at its 1/120 s, where the
#: links near the cloth travel up to 3.1 thicknesses a step: uncut, a fold the upper arm pushed
#: ended 1.23 thicknesses inside it, and so at a share of 3 (3 % of the steps cut); at 2.5, 48 %
#: of the steps in two, 0 inside and 0 crossings over its 4.6 s. Without self-contact a vertex may
#: move as far as the link pushes it, and the Panda swung through a sheet at 1/60 s a step ended
#: 0 mm inside a link either way, at a quarter of the time uncut (docs/robots.md)
COLLIDER_SHARE = 2.5


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _is_count(x, hi: int) -> bool:
    """Whether ``x`` is a whole number in ``[1, hi]`` (an int or an integral float; not inf or
    NaN, which ``int()`` would raise on)."""
    return _is_number(x) and math.isfinite(x) and int(x) == x and 1 <= x <= hi


def _integer(name: str, value, hi: int) -> None:
    if not _is_count(value, hi):
        raise ValueError(f"{name} must be an integer in [1, {hi}], got {value!r}")


@dataclass(frozen=True)
class VBDOptions:
    """The options as given (None where the integrator chooses), checked when made: a bad value
    is a ``ValueError`` naming the option and what it accepts, an unknown name one listing the
    options (:meth:`of`)."""

    #: per step at most (None: chosen, up to ``vbd.MAX_ITERATIONS``, with the substeps)
    iterations: int | None = None
    #: Chebyshev acceleration's spectral radius estimate, in [0, 1) (0: off)
    rho: float = 0.8
    #: the relative residual a step stops at (0: every iteration runs)
    tolerance: float = TOLERANCE
    #: iterations between two measures of the residual
    check_every: int = CHECK_EVERY
    #: 'auto' (chosen from the cloth and dt), an integer, or None (auto where ``iterations`` is
    #: not given, else 1)
    substeps: int | str | None = None
    #: the thicknesses a collider within reach of the cloth may travel in a substep ('auto':
    #: :data:`COLLIDER_SHARE` where the cloth self-collides, else any; None: any)
    collider_share: float | str | None = "auto"
    #: the colliders' contact penalty's stiffness (N/m)
    contact_stiffness: float = 1e4
    #: the self-contact penalty's stiffness (N/m; None: ``contact_stiffness``; 'cloth': as stiff
    #: as the cloth's springs at its median vertex)
    self_contact_stiffness: float | str | None = None
    #: iterations between candidate searches for self-contact (None: chosen, fewer while a
    #: collider moves)
    collision_interval: int | None = None
    #: wall seconds a step may iterate (None: no budget)
    time_budget: float | None = None
    #: Coulomb's μ between layers of the cloth
    self_friction: float = 0.5
    #: long-range attachments to the pins inside the solve
    tethers: bool = False
    #: the grid's block sweeps where the cloth is a grid of Hooke springs
    grid: bool = True
    #: solve each step whole by Newton's method with a sparse factorisation (None: where vbd
    #: chooses its work, on a small cloth; either way only without contacts and spring damping)
    direct: bool | None = None
    #: 'bdf2' or 'euler' (None: bdf2 where ``iterations`` is not given, else euler)
    scheme: str | None = None

    @classmethod
    def of(cls, options: dict) -> VBDOptions:
        """The options of a dict of them; an unknown name is a ``ValueError`` listing the
        options."""
        known = [f.name for f in fields(cls)]
        unknown = sorted(set(options) - set(known))
        if unknown:
            raise ValueError(
                f"vbd has no option {', '.join(map(repr, unknown))}; its options: "
                f"{', '.join(known)}"
            )
        return cls(**options)

    def __post_init__(self):
        if self.scheme is not None and self.scheme not in SCHEMES:
            raise ValueError(
                f"scheme must be one of {', '.join(SCHEMES)}, or None (bdf2 where iterations is "
                f"not given, else euler): the implicit step a substep solves, got {self.scheme!r}"
            )
        if self.iterations is not None:
            _integer("iterations", self.iterations, 100_000)
        if self.collision_interval is not None:
            _integer("collision_interval", self.collision_interval, 10_000)
        _integer("check_every", self.check_every, 10_000)
        tol = self.tolerance
        if not (_is_number(tol) and 0.0 <= tol < math.inf):
            raise ValueError(
                "tolerance must be a number >= 0 (the relative residual: the force imbalance over "
                f"the weight, RMS over the vertices; 0 runs every iteration), got {tol!r}"
            )
        s = self.substeps
        if s not in (None, "auto") and not _is_count(s, 10_000):
            raise ValueError(
                "substeps must be 'auto' (chosen from the cloth and dt), None (auto where "
                f"iterations is not given, else 1) or an integer in [1, 10000], got {s!r}"
            )
        share = self.collider_share
        if share not in (None, "auto") and not (_is_number(share) and 0.0 < share < math.inf):
            raise ValueError(
                f"collider_share must be 'auto' ({COLLIDER_SHARE:g} where the cloth "
                "self-collides, else off), None (off) or a number > 0 (the thicknesses a "
                f"collider within reach of the cloth may travel in a substep), got {share!r}"
            )
        if not (_is_number(self.rho) and 0.0 <= self.rho < 1.0):
            raise ValueError(f"rho must be a number in [0, 1), got {self.rho!r}")
        if not (_is_number(self.contact_stiffness) and 0 < self.contact_stiffness < math.inf):
            raise ValueError(
                "contact_stiffness must be a positive number (N/m), got "
                f"{self.contact_stiffness!r}"
            )
        ks = self.self_contact_stiffness
        if ks not in (None, "cloth") and not (_is_number(ks) and 0 < ks < math.inf):
            raise ValueError(
                "self_contact_stiffness must be None (contact_stiffness), 'cloth' (as stiff as "
                f"the cloth's springs at a vertex) or a positive number (N/m), got {ks!r}"
            )
        budget = self.time_budget
        if budget is not None and not (_is_number(budget) and 0 < budget < math.inf):
            raise ValueError(
                f"time_budget must be None or a positive number of seconds, got {budget!r}"
            )
        if not (_is_number(self.self_friction) and 0.0 <= self.self_friction < math.inf):
            raise ValueError(
                f"self_friction must be a number >= 0 (Coulomb's μ), got {self.self_friction!r}"
            )
        if self.direct is not None and not isinstance(self.direct, bool):
            raise ValueError(
                "direct must be true, false or None (chosen: on a small cloth where iterations "
                f"is not given), got {self.direct!r}"
            )
        for name in ("tethers", "grid"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be true or false, got {getattr(self, name)!r}")
