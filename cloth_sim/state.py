"""What an integrator advances: positions, velocities, time, and the method's own history.

The model (:class:`~cloth_sim.model.ClothModel`) is read-only; a :class:`State` is the part that
changes every step. A method with history (Verlet's previous positions, Kang's last ``Δv``) keeps
it in :attr:`State.history`, so copying a state (a checkpoint before a step) copies everything the
next step depends on.
"""

from __future__ import annotations

import numpy as np


class SimulationDiverged(RuntimeError):
    """A step produced a non-finite or exploding state; the simulator was put back before it."""


class State:
    """``x``, ``v``: ``(n, 3)`` float64 positions and velocities. Time is ``t_base + steps·dt``:
    ``t_base`` moves when ``dt`` changes, so the time of many steps carries no rounding drift."""

    def __init__(self, x: np.ndarray, v: np.ndarray | None = None):
        self.x = np.array(x, dtype=np.float64)
        self.v = np.zeros_like(self.x) if v is None else np.array(v, dtype=np.float64)
        self.t_base = 0.0
        self.steps = 0
        self.history: dict[str, np.ndarray] = {}
        #: the integrator that wrote ``history`` (set by ``Simulator.save_state``)
        self.method: str | None = None

    def time(self, dt: float) -> float:
        return self.t_base + self.steps * dt

    def rebase(self, dt: float) -> None:
        """Fold the steps taken so far into ``t_base`` (before ``dt`` changes)."""
        self.t_base, self.steps = self.time(dt), 0

    def copy_to(self, other: "State") -> None:
        """Make ``other`` equal to this state, reusing its arrays where shapes allow."""
        np.copyto(other.x, self.x)
        np.copyto(other.v, self.v)
        other.t_base, other.steps = self.t_base, self.steps
        for key in list(other.history):
            if key not in self.history:
                del other.history[key]
        for key, value in self.history.items():
            dst = other.history.get(key)
            if dst is None or dst.shape != value.shape:
                other.history[key] = value.copy()
            else:
                np.copyto(dst, value)

    def copy(self) -> "State":
        out = State(self.x, self.v)
        self.copy_to(out)
        return out
