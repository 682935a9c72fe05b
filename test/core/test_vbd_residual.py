"""``vbd``'s residual (:mod:`cloth_sim.integrators.vbd_residual`): the backward-Euler step's force
imbalance relative to the weight, which the step iterates down to its tolerance.

Checked against the step's closed form (one particle on a spring: the imbalance of a given
iterate by hand), against the distance to the converged step (a step of thousands of iterations)
on the grid's blocks and on the general sweep, and for what the counters say when the iterations
are capped too low and when they are not."""

import math

import numpy as np
import pytest
from cloths import one_spring

from cloth_sim import ClothModel, Simulator, colliders
from cloth_sim.integrators.vbd import VBD
from cloth_sim.integrators.vbd_kernels import SUBSTEP_RATIO
from cloth_sim.integrators.vbd_residual import G0

NO_GRAVITY = (0.0, 0.0, 0.0)


def _hanging(n=12):
    """A small, stiff cotton sheet hanging from two corners: the regime the residual is for."""
    return ClothModel.grid(
        n, n, size=(0.5, 0.5), material="cotton", pinned=[(n - 1, 0), (n - 1, n - 1)]
    )


def _one_step(model, iterations, start, tolerance=0.0, **options):
    sim = Simulator(
        model,
        integrator="vbd",
        dt=1 / 60,
        integrator_options={"iterations": iterations, "tolerance": tolerance, **options},
    )
    sim.positions, sim.velocities = start
    sim.step()
    return sim


def test_the_residual_of_one_spring_is_its_force_imbalance_by_hand():
    """One free particle on a spring along x, gravity along −z, no damping, one iteration: the
    residual is the imbalance the sweep found at the step's initial guess (the paper's adaptive
    one: inertia without gravity on a first step, ``x^t + h v``), ``m g − k (l − L) u``, over the
    weight at standard gravity, recomputed here from the state alone."""
    k, m, h = 100.0, 0.5, 0.05
    model = one_spring(k=k, m=m)
    sim = Simulator(
        model, integrator="vbd", dt=h, integrator_options={"iterations": 1, "rho": 0.0}
    )
    x0 = sim.positions.copy()
    x0[1, 0] += 0.1  # stretched by 10 cm
    v0 = np.zeros_like(x0)
    v0[1] = (0.3, 0.0, 0.2)
    sim.positions, sim.velocities = x0, v0
    sim.step()
    guess = x0[1] + h * v0[1]
    d = guess - x0[0]
    length = np.linalg.norm(d)
    force = m * np.array([0.0, 0.0, -9.81]) - k * (length - model.rest_lengths[0]) * d / length
    expected = np.linalg.norm(force) / (m * G0)
    s = sim.integrator_stats
    assert s["last_residual"] == pytest.approx(expected, rel=1e-12)
    assert s["last_residual"] > 0.1


@pytest.mark.parametrize("grid", [True, False])
def test_the_residual_follows_the_distance_to_the_converged_step(grid):
    """From one mid-fall state, steps of more iterations end nearer the converged step (5,000
    iterations: residual below 1e-9) and with a smaller residual, and the residual stays in
    proportion to that distance (their ratio within a factor of 30 over four orders of
    magnitude): on the grid's blocks and on the general sweep, whose residuals are computed
    apart."""
    model = _hanging()
    warm = Simulator(model, integrator="vbd", dt=1 / 60, integrator_options={"iterations": 50})
    warm.step(12)
    start = (warm.positions.copy(), warm.velocities.copy())
    best = _one_step(model, 5000, start, grid=grid)
    assert best.integrator_stats["last_residual"] < 1e-9
    assert (best.integrator_stats["grid_steps"] == 1) == grid
    rows = []
    for iterations in (3, 10, 30, 100, 300):
        sim = _one_step(model, iterations, start, grid=grid)
        dist = math.sqrt(((sim.positions - best.positions) ** 2).sum(axis=1).mean())
        rows.append((iterations, sim.integrator_stats["last_residual"], dist))
    residuals = [r for _, r, _ in rows]
    distances = [d for _, _, d in rows]
    assert all(b < a for a, b in zip(residuals, residuals[1:])), rows
    assert all(b < a for a, b in zip(distances, distances[1:])), rows
    assert residuals[0] / residuals[-1] > 1e3, rows
    ratios = [r / d for _, r, d in rows]
    assert max(ratios) / min(ratios) < 30.0, rows


def test_capped_iterations_say_unconverged_and_enough_say_converged():
    """Capped far below what the step needs, the step ends above the tolerance and says so; with
    room, it stops as soon as a measure is below the tolerance, in fewer iterations than its
    cap, and says it converged. The counters keep the tolerance and count the unconverged
    steps."""
    model = _hanging()
    start = (model.positions.copy(), np.zeros_like(model.positions))
    low = _one_step(model, 2, start, tolerance=1e-3)
    s = low.integrator_stats
    assert s["last_iterations"] == 2 and s["last_residual"] > 1e-3
    assert s["converged"] is False and s["unconverged_steps"] == 1 and s["tolerance"] == 1e-3
    high = _one_step(model, 2000, start, tolerance=1e-3)
    s = high.integrator_stats
    assert s["last_residual"] <= 1e-3 and s["converged"] is True
    assert s["last_iterations"] < 2000 and s["unconverged_steps"] == 0
    # it stopped at the first measure below the tolerance: one run of measures earlier was not
    every = VBD(model).check_every
    earlier = _one_step(model, s["last_iterations"] - every, start, tolerance=1e-3)
    assert earlier.integrator_stats["last_residual"] > 1e-3


def test_the_tolerance_stops_the_iterations_with_colliders_and_self_contact():
    """The colliders' penalty and the self-contacts are part of the balance: a cloth resting on
    a plane (its weight carried by the contact) and a fold pressed on itself still converge to
    the tolerance, with the contacts' forces counted."""
    model = ClothModel.grid(8, 8, 0.05, 0.002, stiffness=200.0, damping=0.0)
    sim = Simulator(
        model,
        integrator="vbd",
        dt=1 / 60,
        colliders=[colliders.Plane(normal=(0, 0, 1), offset=-0.002, friction=0.3)],
        thickness=0.004,
        self_collision=True,
        integrator_options={"iterations": 400, "tolerance": 1e-4},
    )
    sim.step(30)
    s = sim.integrator_stats
    assert s["converged"] and s["last_residual"] <= 1e-4 and s["last_iterations"] < 400
    # the weight rests on the plane: without the contacts' force the imbalance would be ~1
    assert np.all(sim.positions[:, 2] > -0.002)


@pytest.mark.parametrize("bad", [-1e-3, math.inf, "1e-2", True])
def test_a_bad_tolerance_is_refused_naming_it(bad):
    with pytest.raises(ValueError, match="tolerance"):
        VBD(one_spring(), tolerance=bad)


def test_no_gravity_keeps_the_same_unit():
    """The residual's unit is the weight at standard gravity whatever the scene's gravity: a
    cloth in free space still measures its imbalance, and converges."""
    model = _hanging(6)
    sim = Simulator(
        model,
        integrator="vbd",
        dt=1 / 60,
        gravity=NO_GRAVITY,
        integrator_options={"iterations": 500, "tolerance": 1e-6},
    )
    x = model.positions.copy()
    x[:, 2] += 0.01 * np.sin(7 * x[:, 0])
    sim.positions = x
    sim.step()
    assert 0.0 < sim.integrator_stats["last_residual"] <= 1e-6


def test_with_no_options_a_fabric_gets_substeps_that_converge():
    """Named fabric, no options: the step is cut into the fewest substeps whose stiffness over
    inertia is at most SUBSTEP_RATIO (one fewer would exceed it), and every step converges."""
    model = _hanging(16)
    sim = Simulator(model, integrator="vbd", dt=1 / 60)
    sim.step(20)
    s = sim.integrator_stats
    n = s["last_substeps"]
    assert n > 1 and s["unconverged_steps"] == 0 and s["converged"]
    k = np.zeros(model.n_particles)
    c = np.zeros(model.n_particles)
    for (a, b), ks, cs in zip(model.springs, model.stiffness, model.damping):
        k[[a, b]] += ks
        c[[a, b]] += cs
    if model.bending is not None:
        k += model.bending.Q.diagonal()
    free = ~model.pinned

    def worst(parts):
        h = 1 / 60 / parts
        return float(((h * h * k + h * c) / model.masses)[free].max())

    assert worst(n) <= SUBSTEP_RATIO * (1 + 1e-12) < worst(n - 1)
    # iterations given alone: one step of at most that many, as before
    capped = Simulator(model, integrator="vbd", dt=1 / 60, integrator_options={"iterations": 10})
    capped.step()
    assert capped.integrator_stats["last_substeps"] == 1


def test_substeps_are_steps_of_their_own():
    """Without colliders, a step of dt in n substeps is n steps of dt/n to rounding."""
    model = _hanging(10)
    opts = {"iterations": 8, "tolerance": 0.0}
    whole = Simulator(
        model, integrator="vbd", dt=1 / 60, integrator_options={**opts, "substeps": 4}
    )
    parts = Simulator(model, integrator="vbd", dt=1 / 240, integrator_options=opts)
    whole.step(6)
    parts.step(24)
    np.testing.assert_allclose(whole.positions, parts.positions, rtol=0, atol=1e-12)
    assert whole.integrator_stats["last_iterations"] == 4 * 8


def test_a_moving_collider_is_taken_in_parts_over_the_substeps():
    """packed_parts: the step's own poses at its ends, a continuous path between (the end of a
    part is the start of the next), the position interpolated linearly and the rotation on the
    sphere (a quarter turn about z in three parts is 30° a part), each collider on its own path
    (a still one stays where it is)."""
    from scipy.spatial.transform import Rotation

    from cloth_sim.contact.collider_kernels import BOX, NO_COLLIDERS
    from cloth_sim.contact.colliders import packed_parts

    turn = Rotation.from_euler("z", 90, degrees=True).as_matrix()
    packed = NO_COLLIDERS._replace(
        kinds=np.array([BOX, BOX]),
        pos=np.array([[0.6, 0.0, 0.3], [1.0, 1.0, 1.0]]),
        rot=np.stack([turn, np.eye(3)]),
        pos0=np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]),
        rot0=np.stack([np.eye(3), np.eye(3)]),
        geo=np.array([[0.1, 0.1, 0.1, 0.0]] * 2),
        mu=np.array([0.5, 0.5]),
        reach=np.array([0.2, 0.2]),
    )
    (whole,) = packed_parts(packed, 1)
    for a, b in zip(whole, packed):
        np.testing.assert_array_equal(a, b)
    parts = packed_parts(packed, 3)
    for a, b in zip(parts[:-1], parts[1:]):
        np.testing.assert_array_equal(a.pos, b.pos0)
        np.testing.assert_array_equal(a.rot, b.rot0)
    np.testing.assert_array_equal(parts[0].pos0, packed.pos0)
    np.testing.assert_array_equal(parts[-1].rot, packed.rot)
    for k, part in enumerate(parts, start=1):
        np.testing.assert_allclose(part.pos[0], (0.2 * k, 0.0, 0.1 * k), atol=1e-15)
        angle = Rotation.from_matrix(part.rot[0]).as_euler("xyz", degrees=True)
        np.testing.assert_allclose(angle, (0.0, 0.0, 30.0 * k), atol=1e-9)
        np.testing.assert_allclose(part.pos[1], (1.0, 1.0, 1.0), atol=1e-15)
        np.testing.assert_allclose(part.rot[1], np.eye(3), atol=1e-15)
