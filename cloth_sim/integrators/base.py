"""The integrator interface and the linear stability analysis shared by all methods."""

from __future__ import annotations

import numpy as np


class Integrator:
    """Advances the simulator's state ``(x, v)`` by one step of ``dt``, in place.

    Subclasses set ``name``, ``order`` and ``implicit`` and implement :meth:`step`. An integrator
    reads forces through ``system.forces`` (a :class:`~cloth_sim.forces.Forces`), which the
    simulator rebuilds when parameters change, so it never holds stale forces. Methods with history
    (Verlet) rebuild it in :meth:`reset`, which the simulator calls whenever the state, ``dt`` or
    the method changes.
    """

    name: str = ""
    order: int = 0
    implicit: bool = False
    #: True for methods stable at any ``dt`` on a linear system (``stable_dt`` is ``inf``).
    unconditionally_stable: bool = False
    #: After a position correction ``Δx`` (strain limiting), the velocity moves by
    #: ``velocity_follow · Δx / dt``.
    velocity_follow: float = 1.0
    #: True for methods whose stability region misses the imaginary axis near 0 (explicit Euler,
    #: midpoint): an undamped oscillator grows at every dt.
    needs_damping: bool = False

    def __init__(self, system):
        self.system = system

    def reset(self, x: np.ndarray, v: np.ndarray, dt: float) -> None:
        """Rebuild any history from the current state (no-op for one-step methods)."""

    def parameters_changed(self) -> None:
        """Stiffness, damping, masses, pins or external forces changed (no-op by default)."""

    def step(self, x: np.ndarray, v: np.ndarray, dt: float) -> None:
        raise NotImplementedError

    def amplification(self, h: float, omega: float, zeta: float) -> np.ndarray:
        """The matrix taking the method's state to the next step for ``x'' + 2ζω x' + ω² x = 0``:
        2×2 on ``(x, v)`` for one-step methods (a multistep method uses its own history)."""
        raise NotImplementedError

    def stable_dt(self, omega: float, zeta: float = 0.0) -> float:
        """Largest ``dt`` whose step is stable for a mode of frequency ``omega`` and damping ratio
        ``zeta`` (linear theory: spectral radius of :meth:`amplification` ≤ 1). 0 when no step is
        stable, ``inf`` for unconditionally stable methods or ``omega == 0``."""
        if self.unconditionally_stable or omega <= 0:
            return np.inf
        if self.needs_damping and zeta <= 0:
            return 0.0

        def stable(h):
            return np.max(np.abs(np.linalg.eigvals(self.amplification(h, omega, zeta)))) <= 1 + 1e-12

        grid = np.linspace(0.0, 8.0 / omega, 8001)[1:]
        last_ok = 0.0
        for h in grid:
            if not stable(h):
                break
            last_ok = h
        else:
            return np.inf
        lo, hi = last_ok, h
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if stable(mid) else (lo, mid)
        return lo


def oscillator_matrix(omega: float, zeta: float) -> np.ndarray:
    """``J`` of the first-order system ``(x, v)' = J (x, v)`` of a damped oscillator."""
    return np.array([[0.0, 1.0], [-omega * omega, -2.0 * zeta * omega]])
