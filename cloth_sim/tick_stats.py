"""The figures of one tick of the node (or one frame of a recorded run): the body of the package's
``Stats`` message (``msg/Stats.msg``) as one record, read from a simulator in one place. The ROS
adapter copies it into the generated message (:func:`cloth_sim.ros.messages.stats`) and the bag
writer serialises it without ROS (:func:`cloth_sim.bag.cdr.stats`)."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True, kw_only=True)
class TickStats:
    """``msg/Stats.msg`` field for field, in its order, without the header (the units and
    meanings are the message's)."""

    integrator: str
    dt: float
    steps: int
    step_time_mean: float = 0.0
    step_time_max: float = 0.0
    tick_wall_time: float = 0.0
    real_time_factor: float = 0.0
    sim_time: float
    kinetic_energy: float
    potential_energy: float
    max_strain: float
    overruns: int = 0
    stability_margin: float = 0.0
    paused: bool = False
    solver_iterations: int = 0
    solver_residual: float = 0.0
    solver_converged: bool = True

    @classmethod
    def of(cls, sim, *, steps: int, energy: dict | None = None, **timing) -> TickStats:
        """``sim``'s figures now: its method, step, time, energy (``energy`` where the caller
        has it already), largest strain and solver counters (``last_iterations``,
        ``last_residual`` and ``converged`` of an iterative method); ``timing``: the tick's own
        fields (``step_time_mean``, ``real_time_factor``, ``overruns``, ``paused``, …)."""
        energy = sim.energy() if energy is None else energy
        solver = sim.integrator_stats or {}
        return cls(
            integrator=sim.integrator,
            dt=sim.dt,
            steps=int(steps),
            sim_time=sim.time,
            kinetic_energy=energy["kinetic"],
            potential_energy=energy["spring"] + energy["gravity"],
            max_strain=sim.max_strain(),
            solver_iterations=int(solver.get("last_iterations", 0)),
            solver_residual=float(solver.get("last_residual", 0.0)),
            solver_converged=bool(solver.get("converged", True)),
            **timing,
        )


def stability_margin(dt: float, stable_dt: float | None) -> float:
    """``dt / stable_dt``: 0 for an unconditionally stable method (or an unknown limit), inf when
    no step is stable."""
    if stable_dt is None or math.isinf(stable_dt):
        return 0.0
    return dt / stable_dt if stable_dt > 0 else math.inf
