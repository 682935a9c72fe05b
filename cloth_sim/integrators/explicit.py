"""Explicit integrators: three Runge–Kutta tableaus on one stepper, symplectic Euler and Verlet.

The Runge–Kutta methods integrate the first-order system ``(x, v)' = (v, M⁻¹ f(x, v))`` (the
review's eq. 1.10); a method is only its Butcher tableau, as in ``scipy.integrate``.
"""

from __future__ import annotations

import numba
import numpy as np

from ..kernel_cache import keep_true
from ..physics.force_kernels import GATHER_KICK_DRIFT, combine_particle, runge_kutta_fused
from .base import Integrator, VelocityOrigin, matrices, oscillator_matrix
from .registry import register


class ExplicitRungeKutta(Integrator):
    """Explicit Runge–Kutta step driven by a Butcher tableau ``(A, b)``."""

    takes_bending = True

    A: np.ndarray
    b: np.ndarray

    def velocity_origin(self, start_x, dt) -> VelocityOrigin | None:
        """Midpoint's and RK4's: the step's mean. Their end velocity is not the positions'
        difference over the step (it is ``a·dt/2`` ahead of it under a steady force), so a
        particle a stage corrects takes its mean velocity and the correction's (PBD's velocity,
        Müller et al. 2007). Following the correction alone left that ``a·dt/2`` out of the limit
        every step: on a cotton sheet under a strain limit the particle beside a pin kept
        0.2–0.47 m/s on RK4 at any step. (Explicit Euler's positions move by the step's starting
        velocity alone, so no correction of them says what its forces did: it keeps following.)"""
        return VelocityOrigin(start_x, dt, True) if self.order >= 2 else None

    def step(self, state, forces, dt):
        x, v = state.x, state.v
        stages = len(self.b)
        k = self.__dict__.get("_k")
        if k is None or k.shape[1:] != (stages, *x.shape):
            k = self._k = np.empty((2, stages, *x.shape))  # the stages' (dx/dt, dv/dt)
            self._coef = np.empty(stages)
        kx, kv, coef = k[0], k[1], self._coef
        xs = self._buffer("_xs", x)
        if forces.fuses_stages:  # each stage's forces and the next stage's state in one pass
            net, base, inv_mass = forces.spring_term.net, forces.gather_base, forces.inv_mass
            runge_kutta_fused(x, v, self.A, self.b, dt, kx, kv, xs, coef, net, base, inv_mass)
            forces.evaluations += stages
            return
        combine = combine_parallel if forces.spring_term.parallel else _combine
        for i in range(stages):
            if i == 0:  # the first stage is the current state itself; no copy needed
                np.copyto(kx[0], v)
                forces.acceleration(x, v, out=kv[0])
                continue
            # the stage's state: its velocity goes straight into kx[i] (combine reads kx[:i] only)
            np.multiply(self.A[i, :i], dt, out=coef[:i])
            combine(xs, kx[i], x, v, kx, kv, coef[:i])
            forces.acceleration(xs, kx[i], out=kv[i])
        np.multiply(self.b, dt, out=coef)
        combine(x, v, x, v, kx, kv, coef)

    @classmethod
    def spectral_radii(cls, h, omega, zeta):
        """``max |R(hλ)|`` over the oscillator's eigenvalues ``λ = ω(−ζ ± √(ζ²−1))``, with ``R``
        the tableau's stability polynomial ``1 + Σ_k (b·A^{k−1}·1) z^k`` (the eigenvalues of a
        polynomial of a matrix are the polynomial of its eigenvalues): the same as the
        amplification matrix's radius, without building it."""
        h, omega, zeta = (np.asarray(a, dtype=np.float64) for a in (h, omega, zeta))
        root = np.sqrt((zeta * zeta - 1.0).astype(np.complex128))
        radius = 0.0
        for sign in (1.0, -1.0):
            z = h * omega * (-zeta + sign * root)
            r = np.zeros_like(z)
            for g in cls._polynomial()[::-1]:  # Horner
                r = r * z + g
            radius = np.maximum(radius, np.abs(r))
        return radius

    @classmethod
    def _polynomial(cls) -> tuple[float, ...]:
        """Coefficients ``γ_0 … γ_s`` of the stability polynomial."""
        s = len(cls.b)
        coeffs, vec = [1.0], np.ones(s)
        for _ in range(s):
            coeffs.append(float(cls.b @ vec))
            vec = cls.A @ vec
        return tuple(coeffs)

    @classmethod
    def amplification(cls, h, omega, zeta):
        J = oscillator_matrix(omega, zeta)
        h = np.asarray(h, dtype=np.float64)[..., None, None]  # a batch: (..., 2, 2)
        eye = np.eye(2)
        K = [J]
        for i in range(1, len(cls.b)):
            K.append(J @ (eye + h * sum(cls.A[i, j] * K[j] for j in range(i))))
        return eye + h * sum(cls.b[i] * K[i] for i in range(len(cls.b)))


@numba.njit(cache=True)
def _combine(xo, vo, x, v, kx, kv, coef):
    """``xo = x + Σ_j kx[j]·coef[j]`` and ``vo = v + Σ_j kv[j]·coef[j]`` over the non-zero
    coefficients, in one pass (a stage's state, or the step's update in place with ``xo is x``):
    per element the operations, and their order, of the array expressions they replace (a copy,
    then ``+= kx[j]·(dt·a)`` term by term), so the same bits."""
    for p in range(x.shape[0]):
        combine_particle(xo, vo, x, v, kx, kv, coef, p)


@numba.njit(cache=True, parallel=True)
def combine_parallel(xo, vo, x, v, kx, kv, coef):
    """:func:`_combine` on every core (each particle's elements are independent: the same bits);
    for the cloths whose spring forces run on every core, where it was a fifth of an RK4 step at
    128×128 on one."""
    for p in numba.prange(x.shape[0]):
        combine_particle(xo, vo, x, v, kx, kv, coef, p)


@numba.njit(cache=True)
def _verlet_update(x, v, prev, a, dt, pinned):
    """``x' = 2x − x_prev + dt²·a``, ``v' = (3x' − 4x + x_prev)/(2dt)`` (``(x' − x)/dt`` on pins:
    exactly 0 for one at rest), then ``x_prev = x``, ``x = x'``: one pass, no temporaries, the same
    operations in the same order as the array expressions."""
    h2, inv = dt * dt, 2.0 * dt
    for p in range(x.shape[0]):
        for d in range(3):
            new = 2.0 * x[p, d] - prev[p, d] + h2 * a[p, d]
            # a pinned particle moves at constant velocity (0 for a pin, a gripper's otherwise)
            v[p, d] = (
                (new - x[p, d]) / dt
                if pinned[p]
                else (3.0 * new - 4.0 * x[p, d] + prev[p, d]) / inv
            )
            prev[p, d] = x[p, d]
            x[p, d] = new


@register
class ExplicitEuler(ExplicitRungeKutta):
    """Explicit (forward) Euler, order 1: ``x += dt·v``, ``v += dt·a(x, v)``, both from the old
    state (Provot 1995; review eq. 1.11). Unstable for any ``dt`` on an undamped oscillator."""

    name = "explicit_euler"
    order = 1
    needs_damping = True
    A = np.array([[0.0]])
    b = np.array([1.0])


@numba.njit(cache=True)
def kick_drift(x, v, f, inv_mass, dt):
    """Symplectic Euler's update in one pass: ``v += (f·m⁻¹)·dt``, then ``x += v·dt`` with the new
    velocity, each particle once (``inv_mass`` (n, 1) is 0 on pins, which keep their velocity). The
    same operations in the same order as the array expressions it replaced (``a = f·m⁻¹; a *= dt;
    v += a; x += v·dt``), so the same bits, in one pass over the arrays instead of five."""
    for p in range(x.shape[0]):
        w = inv_mass[p, 0]
        for d in range(3):
            v[p, d] += (f[p, d] * w) * dt
            x[p, d] += v[p, d] * dt


@register
class SymplecticEuler(Integrator):
    """Symplectic (semi-implicit) Euler, order 1, in Provot's form (review eq. 1.12): ``v +=
    dt·a(x, v)``, then ``x += dt·v`` with the new velocity. Undamped, it keeps the energy error
    bounded and is stable for ``ω·dt < 2``."""

    name = "symplectic_euler"
    order = 1
    takes_bending = True

    def step(self, state, forces, dt):
        """``f`` the total force, ``v += (f·m⁻¹)·dt``, then ``x += v·dt``: inside the springs'
        gather where the springs are summed on every core and are the last term
        (:attr:`~cloth_sim.physics.forces.Forces.fuses_stages`: one parallel pass), otherwise after
        the force. The same bits either way."""
        x, v, f = state.x, state.v, self._buffer("_a", state.x)
        if forces.fuses_stages:
            forces.gather_update(x, v, f, dt, GATHER_KICK_DRIFT, x, v)
        else:
            kick_drift(x, v, forces.force(x, v, out=f), forces.inv_mass, dt)

    @classmethod
    def amplification(cls, h, omega, zeta):
        w2, c = omega * omega, 2.0 * zeta * omega
        # v' = (1 − h c) v − h ω² x ;  x' = x + h v'
        return matrices([[1.0 - h * h * w2, h * (1.0 - h * c)], [-h * w2, 1.0 - h * c]])


@register
class Midpoint(ExplicitRungeKutta):
    """Explicit midpoint method, second-order Runge–Kutta (review eq. 1.13). Like explicit Euler it
    is unstable on an undamped oscillator (weakly: |R(iωh)|² = 1 + (ωh)⁴/4)."""

    name = "midpoint"
    force_point = 0.5
    order = 2
    needs_damping = True
    A = np.array([[0.0, 0.0], [0.5, 0.0]])
    b = np.array([0.0, 1.0])


@register
class RK4(ExplicitRungeKutta):
    """Classical fourth-order Runge–Kutta (review eq. 1.14); stable for ``ω·dt < 2√2`` undamped."""

    name = "rk4"
    force_point = 0.5
    order = 4
    A = np.array(
        [[0.0, 0.0, 0.0, 0.0], [0.5, 0.0, 0.0, 0.0], [0.0, 0.5, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]]
    )
    b = np.array([1.0, 2.0, 2.0, 1.0]) / 6.0


@register
class Verlet(Integrator):
    """Position (Störmer) Verlet, order 2 (review eq. 1.15): ``x⁺ = 2x − x⁻ + dt²·a(x, v)``.

    It is started consistently, ``x⁻ = x − dt·v + ½dt²·a``, and rebuilt that way whenever the
    state, ``dt`` or the method changes. Its velocity, used for damping and diagnostics, is the
    second-order one-sided estimate ``v = (3x − 4x⁻ + x⁻⁻)/(2dt)`` from the last three positions.
    Stable for ``ω·dt < 2`` undamped; with damping the lagged velocity estimate lowers the limit
    below symplectic Euler's (about 20 % at ζ = 0.1), which :meth:`amplification` accounts for.
    """

    name = "verlet"
    order = 2
    takes_bending = True
    velocity_follow = 1.5  # ∂v/∂x of the BDF2 velocity estimate, times dt

    def reset(self, state, forces, dt):
        x, v = state.x, state.v
        a = forces.acceleration(x, v, out=self._buffer("_a", x))
        state.history["x_prev"] = x - dt * v + 0.5 * dt * dt * a

    def pins_moved(self, state):
        """Pinned particles were placed: keep them at rest (history equal to the new position)."""
        pinned = self.model.pinned
        state.history["x_prev"][pinned] = state.x[pinned]

    def kinematic_velocities(self, state, indices, dt):
        """``x_prev = x − dt·v`` for those particles: with no acceleration ``x⁺ = x + dt·v``."""
        state.history["x_prev"][indices] = state.x[indices] - dt * state.v[indices]

    def step(self, state, forces, dt):
        x, v, prev = state.x, state.v, state.history["x_prev"]
        a = forces.acceleration(x, v, out=self._buffer("_a", x))
        _verlet_update(x, v, prev, a, dt, self.model.pinned)

    @classmethod
    def amplification(cls, h, omega, zeta):
        """3×3, on ``(xₙ, xₙ₋₁, xₙ₋₂)``: ``xₙ₊₁ = 2xₙ − xₙ₋₁ + h²·(−ω²xₙ − c·vₙ)`` with
        ``vₙ = (3xₙ − 4xₙ₋₁ + xₙ₋₂)/(2h)`` and ``c = 2ζω``."""
        w2, c = omega * omega, 2.0 * zeta * omega
        return matrices(
            [
                [2.0 - h * h * w2 - 1.5 * h * c, -1.0 + 2.0 * h * c, -0.5 * h * c],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
            ]
        )


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
