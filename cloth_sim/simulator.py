"""The simulator: a model, its force pipeline, an integrator, constraints and a stability guard."""

from __future__ import annotations

import math

import numba
import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import eigsh

from . import integrators
from .constraints import DEFAULT_STRAIN_LIMIT_PASSES, StrainLimit
from .forces import BUCKLE_TABLE, Forces, buckling_h, spring_coupling_matrix, spring_strains
from .model import BUCKLING, ClothModel


class SimulationDiverged(RuntimeError):
    """A step produced a non-finite or exploding state; the simulator was put back before it."""


@numba.njit(cache=True)
def _state_ok(x, v, vmax2, xmax):
    for p in range(x.shape[0]):
        s = v[p, 0] * v[p, 0] + v[p, 1] * v[p, 1] + v[p, 2] * v[p, 2]
        if not (s <= vmax2):  # also catches NaN
            return False
        for d in range(3):
            if not (abs(x[p, d]) <= xmax):
                return False
    return True


def _check_vector(name: str, value) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be a finite 3-vector, got {value!r}")
    return a


class Simulator:
    """Advances a :class:`~cloth_sim.model.ClothModel` in time.

    >>> from cloth_sim import ClothModel, Simulator
    >>> model = ClothModel.grid(8, 8, 0.05, 0.01, stiffness=1e3, pinned=[(0, 0), (0, -1)])
    >>> sim = Simulator(model, integrator="rk4", dt=1e-3)
    >>> sim.advance(0.1); round(sim.time, 3)
    0.1

    Parameters:
        model: the cloth (never modified; several simulators may share it).
        integrator: a name from :func:`cloth_sim.integrators.available`.
        dt: time step (s).
        gravity: acceleration 3-vector (m/s²).
        wind: 3-vector ``w·W``; particle ``i`` feels ``(n_i·wind)·n_i``. ``None``: no wind.
        strain_limit: Provot's critical deformation rate ``τc`` (0.1 = 10 %), ``None`` for none.
        strain_limit_passes: maximum correction passes per step.
        drag: linear air drag coefficient (N·s/m per particle).
        max_speed, max_coordinate: the stability guard's bounds; a step that leaves them, or
            produces NaN or inf, is undone and raises :class:`SimulationDiverged`.
        integrator_options: keyword options of the integrator (e.g. ``{"solver": "direct"}`` for
            ``implicit_euler``, ``{"sweeps": 3}`` for ``kang``).
    """

    def __init__(self, model: ClothModel, integrator: str = "symplectic_euler", dt: float = 1e-3,
                 gravity=(0.0, 0.0, -9.81), wind=None, strain_limit: float | None = None,
                 strain_limit_passes: int = DEFAULT_STRAIN_LIMIT_PASSES, drag: float = 0.0,
                 max_speed: float = 1e3, max_coordinate: float = 1e6,
                 integrator_options: dict | None = None):
        self.model = model
        self._k = np.array(model.stiffness, dtype=np.float64)
        self._c = np.array(model.damping, dtype=np.float64)
        self._gravity = _check_vector("gravity", gravity)
        self._wind = None if wind is None else _check_vector("wind", wind)
        self._drag = self._check_nonneg("drag", drag)
        self._dt = self._check_dt(dt)
        self._x = np.array(model.positions, dtype=np.float64)
        self._v = np.zeros_like(self._x)
        self._x_good = np.empty_like(self._x)
        self._x_before_correction = np.empty_like(self._x)
        self._limited_springs = np.ascontiguousarray(model.springs[model.strain_limited])
        self._limited_rest = np.ascontiguousarray(model.rest_lengths[model.strain_limited])
        self._v_good = np.empty_like(self._x)
        self._t_base, self._n_steps_since_base = 0.0, 0
        self.steps_taken = 0
        self.max_speed = float(max_speed)
        self.max_coordinate = float(max_coordinate)
        self._mode_cache = None
        self._strain = None
        self._strain_passes = int(strain_limit_passes)
        self.strain_limit = strain_limit
        self.forces = self._build_forces()
        self._integrator = integrators.get(integrator)(self, **(integrator_options or {}))
        self._integrator.reset(self._x, self._v, self._dt)

    # ------------------------------------------------------------------ state
    @property
    def positions(self) -> np.ndarray:
        """``(n, 3)`` positions (a read-only view; assign to change them)."""
        view = self._x.view()
        view.setflags(write=False)
        return view

    @positions.setter
    def positions(self, x) -> None:
        """Place every particle; pinned particles move with it (that is how a gripper drags the cloth)."""
        x = self._check_state("positions", x)
        self._x[:] = x
        self._integrator.reset(self._x, self._v, self._dt)

    @property
    def velocities(self) -> np.ndarray:
        """``(n, 3)`` velocities (a read-only view; assign to change them). Pinned rows are zero."""
        view = self._v.view()
        view.setflags(write=False)
        return view

    @velocities.setter
    def velocities(self, v) -> None:
        v = self._check_state("velocities", v)
        self._v[:] = v
        self._v[self.model.pinned] = 0.0
        self._integrator.reset(self._x, self._v, self._dt)

    def move_pins(self, positions, indices=None) -> None:
        """Move pinned particles to ``positions`` (``(p, 3)``; ``indices`` default to every pinned
        particle, in index order). They stay pinned, at rest; the rest of the cloth is untouched."""
        pinned_idx = np.flatnonzero(self.model.pinned)
        idx = pinned_idx if indices is None else np.asarray(indices, dtype=np.int64).ravel()
        if not np.all(self.model.pinned[idx]):
            raise ValueError("move_pins: every index must be a pinned particle; pinned are "
                             f"{pinned_idx.tolist()}")
        p = np.asarray(positions, dtype=np.float64)
        if p.shape != (len(idx), 3) or not np.all(np.isfinite(p)):
            raise ValueError(f"move_pins: positions must be finite with shape ({len(idx)}, 3), "
                             f"got {p.shape}")
        self._x[idx] = p
        pins_moved = getattr(self._integrator, "pins_moved", None)
        if pins_moved is not None:
            pins_moved(self._x, self.model.pinned)

    @property
    def time(self) -> float:
        """Simulated time (s)."""
        return self._t_base + self._n_steps_since_base * self._dt

    def reset(self) -> None:
        """Back to the model's initial positions, at rest, at time 0; parameters are kept."""
        self._x[:] = self.model.positions
        self._v[:] = 0.0
        self._t_base, self._n_steps_since_base = 0.0, 0
        self._integrator.reset(self._x, self._v, self._dt)

    # ------------------------------------------------------------------ parameters
    @property
    def dt(self) -> float:
        return self._dt

    @dt.setter
    def dt(self, value: float) -> None:
        value = self._check_dt(value)
        self._t_base, self._n_steps_since_base = self.time, 0
        self._dt = value
        self._integrator.reset(self._x, self._v, self._dt)
        self._integrator.parameters_changed()

    @property
    def integrator(self) -> str:
        return self._integrator.name

    def set_integrator(self, name: str, **options) -> None:
        """Switch method (``options`` as for ``integrator_options``); positions and velocities
        carry over."""
        new = integrators.get(name)(self, **options)
        new.reset(self._x, self._v, self._dt)
        self._integrator = new

    @property
    def integrator_stats(self) -> dict:
        """Counters of the current method's linear algebra since it was selected: ``solves``,
        ``cg_iterations`` / ``last_cg_iterations`` / ``cg_not_converged`` (``implicit_euler`` with
        CG), ``factorizations`` (``implicit_euler_prefactored``). Empty for explicit methods."""
        stats = getattr(self._integrator, "stats", None)
        return dict(stats()) if stats is not None else {}

    def stiffness(self, family: str) -> np.ndarray:
        """Per-spring stiffness of a family (copy)."""
        return self._k[self.model.family == self.model.family_index(family)].copy()

    def set_stiffness(self, family: str, k: float) -> None:
        """Set every spring of ``family`` to stiffness ``k`` (N/m, ≥ 0); applies at the next step."""
        self._set_family(self._k, "stiffness", family, k)

    def set_damping(self, family: str, c: float) -> None:
        """Set every spring of ``family`` to damping ``c`` (N·s/m, ≥ 0); applies at the next step."""
        self._set_family(self._c, "damping", family, c)

    @property
    def gravity(self) -> np.ndarray:
        return self._gravity.copy()

    @gravity.setter
    def gravity(self, g) -> None:
        self._gravity = _check_vector("gravity", g)
        self._parameters_changed(modes=False)

    @property
    def wind(self):
        return None if self._wind is None else self._wind.copy()

    @wind.setter
    def wind(self, w) -> None:
        self._wind = None if w is None else _check_vector("wind", w)
        self._parameters_changed(modes=False)

    @property
    def drag(self) -> float:
        return self._drag

    @drag.setter
    def drag(self, value: float) -> None:
        self._drag = self._check_nonneg("drag", value)
        self._parameters_changed(modes=False)

    @property
    def strain_limit(self) -> float | None:
        return None if self._strain is None else self._strain.tau

    @strain_limit.setter
    def strain_limit(self, tau: float | None) -> None:
        self._strain = None if tau is None else StrainLimit(self.model, tau, self._strain_passes)

    @property
    def active_terms(self) -> tuple[str, ...]:
        """Force terms the pipeline evaluates (see :mod:`cloth_sim.forces`)."""
        return self.forces.active_terms

    @property
    def force_evaluations(self) -> int:
        return self.forces.evaluations + self._evaluations_before

    # ------------------------------------------------------------------ stepping
    def step(self, n: int = 1) -> None:
        """Take ``n`` steps of ``dt``. On divergence the state before the failing step is restored
        and :class:`SimulationDiverged` is raised."""
        x, v, dt = self._x, self._v, self._dt
        integ = self._integrator
        vmax2, xmax = self.max_speed ** 2, self.max_coordinate
        for _ in range(int(n)):
            np.copyto(self._x_good, x)
            np.copyto(self._v_good, v)
            integ.step(x, v, dt)
            if self._strain is not None:
                self._apply_strain_limit(x, v, dt, integ.velocity_follow)
            if not _state_ok(x, v, vmax2, xmax):
                self._diverged()
            self._n_steps_since_base += 1
            self.steps_taken += 1

    def advance(self, t: float) -> int:
        """Step until ``time >= t`` in whole steps; returns the number of steps taken."""
        n = max(0, math.ceil((t - self.time) / self._dt - 1e-9))
        self.step(n)
        return n

    # ------------------------------------------------------------------ diagnostics
    def energy(self) -> dict:
        """Kinetic, spring and gravitational energy (J); gravity's is ``−Σ m_i g·x_i``."""
        m = self.model.masses
        return {
            "kinetic": 0.5 * float(np.sum(m * np.einsum("ij,ij->i", self._v, self._v))),
            "spring": self.forces.spring_energy(self._x),
            "gravity": -float(np.sum(m * (self._x @ self._gravity))),
        }

    def strains(self, limited_only: bool = False) -> np.ndarray:
        """``(l − L)/L`` per spring (every spring, or only the strain-limited ones)."""
        if limited_only:
            return spring_strains(self._x, self._limited_springs, self._limited_rest)
        return spring_strains(self._x, self.model.springs, self.model.rest_lengths)

    def max_strain(self) -> float:
        """Largest strain over the structural and shear springs (every spring of a network)."""
        s = self.strains(limited_only=True)
        return float(s.max()) if len(s) else 0.0

    def fastest_mode(self) -> tuple[float, float]:
        """``(ω_max, ζ)``: the highest natural frequency of ``M⁻¹K`` over the free particles,
        linearised about the rest shape, and that mode's damping ratio ``qᵀCq / 2ω``.

        ``K = Σ k_eff u uᵀ`` over the springs with ``u`` the rest direction (Choi–Ko buckling pairs
        count with the stiffer of their two branches). ω_max comes from a Lanczos eigensolver, not a
        Gershgorin bound, so it is tight (the 16×16 test cloth: 3.15·√(k/m))."""
        if self._mode_cache is None:
            self._mode_cache = self._compute_fastest_mode()
        return self._mode_cache

    def stable_dt(self) -> float:
        """Largest ``dt`` the current method is expected to survive, from ω_max and its damping
        (``inf`` for unconditionally stable methods, 0 for a method with no stable step)."""
        integ = self._integrator
        if integ.unconditionally_stable:
            return math.inf
        if hasattr(integ, "linear_stable_dt"):  # no scalar mode model: analyse the whole system
            key = integ.name
            if self._stable_dt_cache.get("key") != key:
                self._stable_dt_cache = {"key": key, "value": integ.linear_stable_dt()}
            return self._stable_dt_cache["value"]
        omega, zeta = self.fastest_mode()
        return integ.stable_dt(omega, zeta)

    # ------------------------------------------------------------------ internals
    _evaluations_before = 0
    _stable_dt_cache: dict = {}

    def _build_forces(self) -> Forces:
        return Forces(self.model, self._k, self._c, self._gravity, self._wind, self._drag)

    def _parameters_changed(self, modes: bool = True) -> None:
        self._evaluations_before += self.forces.evaluations
        self.forces = self._build_forces()
        if modes:
            self._mode_cache = None
        self._stable_dt_cache = {}
        self._integrator.parameters_changed()

    def _set_family(self, arr, what, family, value):
        fi = self.model.family_index(family)
        value = float(value)
        if not (math.isfinite(value) and value >= 0):
            raise ValueError(f"{what}.{family} must be a finite number >= 0, got {value}")
        arr[self.model.family == fi] = value
        self._parameters_changed()

    def _apply_strain_limit(self, x, v, dt, follow):
        start = self._x_before_correction
        np.copyto(start, x)
        if self._strain.apply(x):
            v += (follow / dt) * (x - start)

    def _diverged(self):
        bad_t = self.time + self._dt
        np.copyto(self._x, self._x_good)
        np.copyto(self._v, self._v_good)
        self._integrator.reset(self._x, self._v, self._dt)
        limit = self.stable_dt()
        raise SimulationDiverged(
            f"the {self.integrator} step from t={self.time:.6g} s to t={bad_t:.6g} s diverged "
            f"(non-finite value, speed above {self.max_speed:g} m/s or coordinate above "
            f"{self.max_coordinate:g} m) with dt={self._dt:g} s; the stable limit estimate is "
            f"stable_dt()={limit:.4g} s. The state before that step was restored.")

    def _check_state(self, name, a):
        a = np.asarray(a, dtype=np.float64)
        if a.shape != self._x.shape:
            raise ValueError(f"{name} must have shape {self._x.shape}, got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} must be finite")
        return a

    @staticmethod
    def _check_dt(dt):
        dt = float(dt)
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a finite number > 0, got {dt}")
        return dt

    @staticmethod
    def _check_nonneg(name, value):
        value = float(value)
        if not (math.isfinite(value) and value >= 0):
            raise ValueError(f"{name} must be a finite number >= 0, got {value}")
        return value

    def rest_matrices(self) -> tuple[sp.csr_matrix, sp.csr_matrix]:
        """``(K, C)``: ``3n×3n`` stiffness and damping matrices ``Σ k uuᵀ`` and ``Σ c uuᵀ`` over the
        springs, linearised about the rest shape (``u`` the rest directions; Choi–Ko buckling pairs
        count with the stiffer of their two branches). The force is ``−K·δx − C·v`` near rest."""
        model = self.model
        n = model.n_particles
        s = model.springs
        d = model.positions[s[:, 1]] - model.positions[s[:, 0]]
        u = d / np.linalg.norm(d, axis=1)[:, None]
        k_eff = self._k.copy()
        buck = model.kind == BUCKLING
        if buck.any():
            d2h_max = float(np.max(np.abs([buckling_h(r)[2] for r in
                                           np.linspace(0, 1, len(BUCKLE_TABLE))])))
            L = model.rest_lengths[buck]
            k_eff[buck] = np.maximum(k_eff[buck], k_eff[buck] * d2h_max / L ** 3)
        return _axial_matrix(s, u, k_eff, n), _axial_matrix(s, u, self._c, n)

    def _compute_fastest_mode(self) -> tuple[float, float]:
        model = self.model
        free = ~model.pinned
        if not free.any() or model.n_springs == 0:
            return 0.0, 0.0
        K, C = self.rest_matrices()
        dofs = np.repeat(free, 3)
        w = np.repeat(1.0 / np.sqrt(model.masses), 3)[dofs]
        Dm = sp.diags(w)
        A = (Dm @ K[dofs][:, dofs] @ Dm).tocsc()
        if A.shape[0] <= 3:
            vals, vecs = np.linalg.eigh(A.toarray())
            lam, q = vals[-1], vecs[:, -1]
        else:
            vals, vecs = eigsh(A, k=1, which="LA", tol=1e-8)
            lam, q = vals[0], vecs[:, 0]
        omega = math.sqrt(max(lam, 0.0))
        if omega == 0.0:
            return 0.0, 0.0
        Cm = (Dm @ C[dofs][:, dofs] @ Dm)
        zeta = float(q @ (Cm @ q)) / (2.0 * omega)
        return omega, zeta


def _axial_matrix(springs, u, k, n):
    """Sparse ``3n×3n`` ``Σ k uuᵀ`` assembled over the springs (stiffness-matrix pattern)."""
    blocks = -k[:, None, None] * np.einsum("si,sj->sij", u, u)
    return spring_coupling_matrix(springs, blocks, blocks, n)
