"""Every numba kernel the CPU backend runs, compiled ahead into numba's on-disk cache.

:func:`compile_kernels` runs each kernel once on a tiny cloth, so that a real-time loop (the
node, the benchmarks) never compiles inside a tick; ``make install`` runs its parts
(:data:`COMPILE_PARTS`) in processes of their own side by side, then once more to find them all in
the cache. Where its time goes, kernel by kernel: ``cloth-sim bench compile``.
"""

from __future__ import annotations

import time

import numpy as np

from . import integrators
from .constraints.strain_limit import nearest_attachments
from .constraints.strain_limit_kernels import attachment_pass_parallel
from .contact import colliders as col
from .contact.colliders import Plane
from .contact.self_collision import SelfCollision
from .integrators.explicit import combine_parallel
from .integrators.vbd import PARALLEL_MIN_VERTICES
from .model import ClothModel
from .physics.force_kernels import (
    GATHER_ACCELERATION,
    GATHER_FORCE,
    GATHER_KICK_DRIFT,
    GATHER_RK_STAGE,
    runge_kutta_fused,
    spring_forces_gather,
)
from .physics.forces import gather_arrays
from .sensors.camera import DepthCamera
from .simulator import Simulator

__all__ = ["COMPILE_PARTS", "compile_grid_contacts", "compile_kernels"]


def compile_kernels(part: str | None = None) -> float:
    """Run every compiled (numba) kernel once, on a 4×4 cloth: each integrator with both spring
    models, wind, drag, the strain limit (both methods), contacts with each collider shape,
    self-collision and the energy and strain reports; returns the seconds it took. The kernels are
    compiled on first use and kept in numba's on-disk cache; a real-time loop calls this before it
    starts, so that no step compiles inside a tick (what a first step compiling costs, and this
    call with the cache warm: docs/BENCHMARKS.md §7).

    ``part`` (one of :data:`COMPILE_PARTS`) runs only that part's kernels: ``make install``
    compiles the parts in processes of their own side by side (numba compiles on one core), then
    calls this once more to find them all in the cache."""

    if part is not None and part not in COMPILE_PARTS:
        raise ValueError(f"part must be one of {', '.join(COMPILE_PARTS)} or None, got {part!r}")
    t0 = time.perf_counter()
    for name in COMPILE_PARTS if part is None else (part,):
        _COMPILERS[name]()
    return time.perf_counter() - t0


def _compile_steps() -> None:
    """The integrators' steps with both spring models, the strain limit (both methods), a
    material's bending, the parallel spring gather and fused Runge–Kutta step, the long-range
    attachments on every core, and the energy and strain reports."""

    for model_name in ("provot", "choi_ko"):
        model = ClothModel.grid(
            4, 4, 0.1, 0.01, stiffness=100.0, damping=0.1, pinned=[(0, 0)], model=model_name
        )
        for name in integrators.available():
            sim = Simulator(
                model, integrator=name, dt=1e-4, wind=(0.0, 0.0, 1.0), drag=0.01, strain_limit=0.1
            )
            sim.step(2)
            sim.energy()
            sim.max_strain()
        # the strain limit's projection method
        Simulator(model, dt=1e-4, strain_limit=0.1, strain_limit_method="projection").step(2)
        # a material's bending: its own term (small cloths) and inside vbd's vertex solve; its
        # energy (the node's statistics and energy balance, every tick)
        fabric = ClothModel.grid(4, 4, size=(0.1, 0.1), material="denim", pinned=[(0, 0)])
        for name in ("symplectic_euler", "vbd"):
            bent = Simulator(fabric, integrator=name, dt=1e-5)
            bent.step(2)
            bent.energy()
        sim = Simulator(model, dt=1e-4)
        # the parallel gather, which only cloths above forces.PARALLEL_MIN_SPRINGS use: with the
        # state's own (writable) arrays, updating them or not, and with read-only views (reports)
        term = sim.forces.spring_term
        springs = gather_arrays(
            term.springs, term.rest, term.k, term.c, term.kind, True, model.n_particles
        )
        gravity, inv_mass = sim.forces.terms[0].force, sim.forces.inv_mass
        gather = (tuple(springs), gravity, np.zeros_like(sim.positions), inv_mass, 1e-4)
        x, v = sim.positions.copy(), sim.velocities.copy()
        k = np.zeros((2, 2, *x.shape))
        stage = (x, v, k[0], k[1], np.ones(2))
        spring_forces_gather(x, v, *gather, GATHER_KICK_DRIFT, x, v, stage)
        spring_forces_gather(x, v, *gather, GATHER_RK_STAGE, x, v, stage)
        for mode in (GATHER_FORCE, GATHER_ACCELERATION):
            spring_forces_gather(
                sim.positions,
                sim.velocities,
                *gather,
                mode,
                np.zeros((1, 3)),
                np.zeros((1, 3)),
                stage,
            )
        # the whole fused Runge–Kutta step, and the stages' update on every core (wind or drag
        # after the springs)
        runge_kutta_fused(
            x,
            v,
            np.zeros((2, 2)),
            np.ones(2),
            1e-4,
            k[0],
            k[1],
            np.zeros_like(x),
            np.zeros(2),
            tuple(springs),
            gravity,
            inv_mass,
        )
        combine_parallel(x, v, x, v, k[0], k[1], np.ones(2))
        # the long-range attachments on every core, which only cloths from
        # constraints.PARALLEL_MIN_PARTICLES on use (a 64×64 node compiled them in its first tick)
        anchor, reach = nearest_attachments(model)
        attachment_pass_parallel(x, anchor, reach, 0.1)


def _compile_contacts_all() -> None:
    """Contacts with every collider shape (moving too) and self-collision under both spring
    models, on the contact stage and inside vbd; the depth camera over them; vbd's general sweep
    on every core, and the grid's with a time budget."""

    for model_name in ("provot", "choi_ko"):
        model = ClothModel.grid(
            4, 4, 0.1, 0.01, stiffness=100.0, damping=0.1, pinned=[(0, 0)], model=model_name
        )
        for name in ("symplectic_euler", "vbd"):  # the contact stage; vbd's own, moving too
            sim = _compile_contacts(model, name)
        # the depth camera's kernels (triangles, each collider shape)
        DepthCamera(
            width=8,
            height=6,
            fx=5.0,
            fy=5.0,
            cx=3.5,
            cy=2.5,
            position=(0.2, 0.2, 1.0),
            noise="kinect",
        ).render(sim)
    # vbd's sweep on every core, which cloths from vbd.PARALLEL_MIN_VERTICES vertices use (the
    # T-shirt's first step compiled it for 8 s): one signature serves with and without contacts
    # (the general sweep: a grid without contacts takes the grid's own, compiled above, whose
    # chunks do not change its signature); and the grid's with a time budget (one call an
    # iteration, Chebyshev's step from Python)
    big = _parallel_grid()
    Simulator(big, integrator="vbd", dt=1e-4, integrator_options={"grid": False}).step(1)
    Simulator(big, integrator="vbd", dt=1e-4, integrator_options={"time_budget": 1.0}).step(1)


def _parallel_grid() -> ClothModel:
    """The smallest square grid at vbd.PARALLEL_MIN_VERTICES: one that runs vbd's sweeps on
    every core."""

    side = int(np.ceil(np.sqrt(PARALLEL_MIN_VERTICES)))
    return ClothModel.grid(side, side, 0.02, 0.01, stiffness=100.0, pinned=[(0, 0)])


def compile_grid_contacts(model: ClothModel | None = None) -> None:
    """``vbd`` on a grid's blocks with a collider and no self-contact (drape and table at
    ``vbd``): the colours' sweep with the contact pass, ~50 s of numba's compilation alone (their
    first tick paid it until :func:`compile_kernels` ran this): its part ``grid_contacts``,
    which ``make install`` compiles in a process of its own."""

    model = _parallel_grid() if model is None else model
    Simulator(model, integrator="vbd", dt=1e-4, colliders=[Plane(offset=-1.0)]).step(1)


#: :func:`compile_kernels`' parts, each a process of its own in ``make install``
COMPILE_PARTS = ("grid_contacts", "contacts", "steps")
_COMPILERS = {
    "grid_contacts": compile_grid_contacts,
    "contacts": _compile_contacts_all,
    "steps": _compile_steps,
}


def _compile_contacts(model, integrator: str) -> "Simulator":
    """Contacts with every collider shape, one of them moving, and self-collision; returns the
    simulator."""

    sim = Simulator(
        model,
        integrator=integrator,
        dt=1e-4,
        self_collision=True,
        thickness=0.01,
        colliders=[
            col.Plane(friction=0.5),
            col.Sphere(radius=0.1, friction=0.1),
            col.Box(half_extents=(0.1, 0.1, 0.1)),
            col.Capsule(radius=0.05),
            col.Cylinder(radius=0.05, length=0.1),
            col.Mesh(
                ([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1]], [[0, 2, 1], [0, 1, 3]]),
                position=(0.1, 0.1, -0.05),
            ),
        ],
    )
    sim.set_collider_pose(1, (0.0, 0.0, -0.5))
    sim.step(2)
    # the search for some particles' pairs alone (vbd's during its iterations where few vertices
    # met their bounds), which a short run need not make
    touched = np.zeros(model.n_particles, np.bool_)
    touched[0] = True
    SelfCollision(model, thickness=0.01, enabled=True).candidates_touching(
        sim.positions, np.full(model.n_particles, 0.005), touched
    )
    for collider in sim.colliders:  # the signed distances users and the node ask for
        collider.signed_distance(sim.positions)
    return sim
