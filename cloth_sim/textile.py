"""The textile world's standard tests, run on the simulator's own forces.

* **Cantilever** (ASTM D1388, Peirce 1930): a strip clamped at one end overhangs horizontally under
  its weight. The bending length ``c = (G/(w·g))^(1/3)`` sets its shape alone: an inextensible
  heavy elastica of overhang ``l`` has a chord angle that depends only on ``l/c`` (41.49° at ``l =
  2c``, hence the standard's 41.5° line). The test strip overhangs ``l = 2c`` of the fabric's
  expected ``c``; the chord angle it settles at is turned back into ``c`` by solving the elastica
  (:func:`elastica_chord_angle`; Peirce's closed-form approximation, 2 % off at 41.5°, is printed
  beside it).
* **Strip tensile** (ISO 13934-1): a 50 mm × 200 mm strip pulled at both ends to 0.1 % strain;
  the force per width over the strain is the tensile stiffness (N/m).
* **Cusick drape** (ISO 9073-9, BS 5058): a 30 cm disc of fabric held on an 18 cm support drapes;
  the drape coefficient is ``(A_shadow − A_support)/(A_specimen − A_support)``: 1 for a fabric
  that does not bend, near 0 for one that hangs straight down.

The cantilever is simulated as a user would: the strip released level and stepped by ``vbd``
at 1/60 s with its defaults, in air, until it is at rest (its statics, :func:`settle`, stay as
the reference: Newton's method on the total potential energy, the springs' and the bending's
Jacobian and a line search, which is what a damped simulation reaches at rest, without the
wait). The tensile test is statics. The drape, whose folds depend on the way down, is simulated
until the cloth is at rest: by symplectic Euler at 0.9 of its stable step, or by ``vbd``.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from .kernel_cache import keep_true
from .materials import resolve
from .materials.fabric import G_ACCEL
from .model import ClothModel
from .physics.bending import Bending
from .simulator import Simulator

DIRECTIONS = ("warp", "weft")


# ---------------------------------------------------------------------------- closed forms
def elastica_chord_angle(ratio: float) -> float:
    """The chord angle (degrees below horizontal, clamp to tip) of an inextensible heavy
    cantilever of overhang ``l`` with ``ratio = l/c``: ``φ'' = −(l/c)³ (1 − s) cos φ`` on
    ``s ∈ [0, 1]``, ``φ(0) = 0``, ``φ'(1) = 0`` (no moment at the free tip). Solved by shooting on
    the clamp's curvature ``φ'(0) ≤ λ/2`` (the linear beam's, which the nonlinear one never
    exceeds: ``cos φ ≤ 1``)."""
    lam = float(ratio) ** 3

    def rhs(s, y):  # φ, φ', and the tip's position (y, z) along the way
        return [y[1], -lam * (1.0 - s) * math.cos(y[0]), math.cos(y[0]), math.sin(y[0])]

    def shoot(k0):
        return solve_ivp(rhs, (0.0, 1.0), [0.0, k0, 0.0, 0.0], rtol=1e-11, atol=1e-13).y[:, -1]

    # bracket from above: φ'(1) > 0 at λ/2; halve until it turns negative (from 0 itself, a
    # heavy strip's φ would wind past the vertical onto another branch)
    hi = 0.5 * lam
    lo = 0.5 * hi
    while shoot(lo)[1] > 0.0:
        hi, lo = lo, 0.5 * lo
    k0 = brentq(lambda k: shoot(k)[1], lo, hi, xtol=1e-14 * lam)
    _, _, y, z = shoot(k0)
    return math.degrees(math.atan2(z, y))


def bending_length_from_angle(overhang: float, angle_deg: float) -> float:
    """The bending length whose elastica of this overhang has this chord angle (m)."""
    ratio = brentq(lambda r: elastica_chord_angle(r) - angle_deg, 0.05, 8.0, xtol=1e-10)
    return overhang / ratio


def peirce_bending_length(overhang: float, angle_deg: float) -> float:
    """Peirce's approximation ``c = l·(cos(θ/2)/(8 tan θ))^(1/3)``."""
    t = math.radians(angle_deg)
    return overhang * (math.cos(t / 2) / (8 * math.tan(t))) ** (1.0 / 3.0)


# ---------------------------------------------------------------------------- statics
def potential(sim: Simulator, x: np.ndarray, external=None) -> float:
    """The springs', the bending's and gravity's potential energy at ``x`` (J), and that of
    constant ``external`` forces (n, 3) when given."""
    e = sim.forces.spring_energy(x) - float(np.sum(sim.model.masses * (x @ sim.gravity)))
    if external is not None:
        e -= float(np.sum(external * x))
    return e


def settle(sim: Simulator, tol: float = 1e-6, max_iterations: int = 200, external=None) -> int:
    """Bring the free particles to a static equilibrium of the simulator's forces (velocities 0),
    with constant ``external`` forces (n, 3) besides: Newton's method with the positive
    semi-definite part of the force Jacobian (and a vanishing multiple of the identity, for a
    cloth held by nothing: its rigid motions cost no energy) and a backtracking line search on
    :func:`potential`. Stops when the largest free force is below ``tol`` × the heaviest
    particle's weight (or the external forces' largest), or when no step lowers the energy any
    more (rounding); returns the iterations taken."""
    model = sim.model
    free = np.repeat(~model.pinned, 3)
    x = sim.positions.copy()
    zero = np.zeros_like(x)
    ext = zero if external is None else np.asarray(external, np.float64)
    scale = tol * max(G_ACCEL * float(model.masses.max()), float(np.abs(ext).max()))
    e = potential(sim, x, ext)
    it = 0
    for it in range(max_iterations):
        f = (sim.forces.force(x, zero) + ext).ravel()
        if np.abs(f[free]).max() < scale:
            break
        dfdx, _ = sim.forces.jacobians(x, zero, clamp=True)
        H = -dfdx[free][:, free]
        H = H + (1e-12 * abs(H.diagonal()).max()) * sp.identity(H.shape[0], format="csr")
        dx = spla.spsolve(H.tocsc(), f[free])
        step = 1.0
        while True:
            trial = x.copy().ravel()
            trial[free] += step * dx
            trial = trial.reshape(-1, 3)
            et = potential(sim, trial, ext)
            if et <= e:
                break
            step *= 0.5
            if step < 1e-8:  # the energy is at its rounding: no step lowers it
                sim.positions = x
                sim.velocities = zero
                return it
        x, e = trial, et
    sim.positions = x
    sim.velocities = zero
    return it


# ---------------------------------------------------------------------------- the tests
def _direction(direction: str) -> int:
    """0 for warp, 1 for weft; anything else refused naming the accepted ones."""
    if direction not in DIRECTIONS:
        raise ValueError(f"direction: expected one of {', '.join(DIRECTIONS)}, got {direction!r}")
    return DIRECTIONS.index(direction)


def _strip(
    fabric,
    length_cells: int,
    across_cells: int,
    length: float,
    width: float,
    direction: str,
    clamp_rows: int,
    pin_far: bool = False,
):
    """A strip along ``direction`` (warp: +y, the rows; weft: +x, the columns) with
    ``clamp_rows`` lines pinned at its start (and the same at its end with ``pin_far``); returns
    the model and a function giving the particles of line ``k`` along the strip."""
    _direction(direction)
    n_along, n_across = length_cells + 1, across_cells + 1
    ends = list(range(clamp_rows)) + (
        list(range(n_along - clamp_rows, n_along)) if pin_far else []
    )
    if direction == "warp":
        rows, cols, size = n_along, n_across, (width, length)
        pinned = [(r, c) for r in ends for c in range(cols)]

        def line(k):
            return np.arange(cols) + k * cols
    else:
        rows, cols, size = n_across, n_along, (length, width)
        pinned = [(r, c) for c in ends for r in range(rows)]

        def line(k):
            return np.arange(rows) * cols + k

    model = ClothModel.grid(rows=rows, cols=cols, size=size, material=fabric, pinned=pinned)
    return model, line


#: how a cantilever reaches its rest: ``vbd`` (simulated from its release at 1/60 s with ``vbd``'s
#: own defaults, in air: what a user gets) or ``statics`` (:func:`settle`, the equilibrium itself)
METHODS = ("vbd", "statics")

#: how a drape specimen is simulated to its rest: ``explicit`` (symplectic Euler at 0.9 of its
#: stable step) or ``vbd`` (its defaults at 1/60 s)
DRAPE_METHODS = ("explicit", "vbd")

#: air drag on a simulated specimen, as its particles' relaxation time (s): a strip or disc of a
#: fraction of a gram in air stops within a second or two (undamped, it swings for ever: a
#: fabric's springs carry no damping of their own)
AIR_RELAXATION = 0.1


#: a simulated specimen is at rest when no particle moves faster than this (m/s)
REST_SPEED = 1e-3


def released(model: ClothModel, integrator: str, dt: float) -> Simulator:
    """A simulator of ``model`` with air drag of :data:`AIR_RELAXATION` on its median particle."""
    return Simulator(
        model, integrator=integrator, dt=dt, drag=float(np.median(model.masses)) / AIR_RELAXATION
    )


def until_rest(sim: Simulator, seconds: float, rest_speed: float) -> None:
    """Advance ``sim`` until no particle moves faster than ``rest_speed`` (m/s) at two checks in
    a row, 0.25 s apart (one slow check can be a swing's turning point: a cotton strip at 16×4 read
    0.9 mm/s at 0.75 s, 2.7 % short of where it came to rest), or ``seconds`` have passed."""
    slow = 0
    while sim.time < seconds:
        sim.advance(min(sim.time + 0.25, seconds))
        slow = slow + 1 if np.abs(sim.velocities).max() < rest_speed else 0
        if slow == 2:
            break


def cantilever(
    material,
    grid: int = 32,
    across: int = 3,
    direction: str = "warp",
    method: str = "vbd",
    seconds: float = 10.0,
    rest_speed: float = REST_SPEED,
) -> dict:
    """The virtual cantilever test: a strip of ``grid`` cells over its overhang ``l = 2c`` and
    ``across`` cells over 25 mm, two lines clamped, brought to rest by ``method``
    (:data:`METHODS`: released level and stepped by ``vbd`` at 1/60 s with its defaults, in air,
    until :func:`until_rest` or ``seconds``; or its equilibrium by :func:`settle`). ``vbd``
    solves such a strip's steps directly (:mod:`~cloth_sim.integrators.vbd_newton`): its
    vertices weigh micrograms beside springs of a real fabric.
    Returns the expected bending length ``(G/(w·g))^(1/3)``, the measured one (the elastica
    through the chord angle at rest), Peirce's from the same angle, the angle, the relative error,
    and how it came to rest."""
    fabric = resolve(material)
    d = _direction(direction)
    if int(grid) != grid or grid < 4:
        raise ValueError(
            f"grid: expected an integer >= 4 (cells along the overhang), got {grid!r}"
        )
    if method not in METHODS:
        raise ValueError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    c = fabric.bending_length(d)
    overhang = 2.0 * c
    a = overhang / grid
    model, line = _strip(fabric, grid + 1, across, a * (grid + 1), 0.025, direction, 2)
    rest = {}
    if method == "statics":
        sim = Simulator(model, integrator="vbd", dt=1e-3)
        rest["newton_iterations"] = settle(sim)
    else:
        sim = released(model, "vbd", 1.0 / 60)
        until_rest(sim, seconds, rest_speed)
        rest["settled_at"] = sim.time
        rest["speed_at_end"] = float(np.abs(sim.velocities).max())
    x = sim.positions
    root, tip = x[line(1)].mean(axis=0), x[line(grid + 1)].mean(axis=0)
    chord = tip - root
    run = chord[1] if direction == "warp" else chord[0]
    angle = math.degrees(math.atan2(-chord[2], run))
    measured = bending_length_from_angle(overhang, angle)
    return {
        "test": "cantilever",
        "method": method,
        "direction": direction,
        "grid": f"{grid}×{across + 1}",
        "expected": c,
        "measured": measured,
        "peirce": peirce_bending_length(overhang, angle),
        "angle_deg": angle,
        "expected_angle_deg": elastica_chord_angle(2.0),
        "error": measured / c - 1.0,
        **rest,
    }


def tensile(material, grid: int = 32, direction: str = "warp", strain: float = 1e-3) -> dict:
    """The virtual strip tensile test: a 50 mm × 200 mm strip, ``grid`` cells along it and
    ``grid/4`` across, pulled at its two ends by a stress (force per width, spread over each end
    line by the width each particle stands for) that would stretch the fabric by ``strain``, the
    ends free to narrow as the middle does (the clamps of a real test hold them; here they would
    add the blocked contraction of a fabric with a high Poisson's ratio to the reading); the
    stress over the measured strain beside the fabric's stretch in that direction."""
    fabric = resolve(material)
    if int(grid) != grid or grid < 4:
        raise ValueError(f"grid: expected an integer >= 4 (cells along the strip), got {grid!r}")
    across = max(1, int(grid) // 4)
    length, width = 0.2, 0.05
    model, line = _strip(fabric, grid, across, length, width, direction, 0)
    sim = Simulator(model, integrator="vbd", dt=1e-3, gravity=(0.0, 0.0, 0.0))
    axis = 1 if direction == "warp" else 0
    expected = fabric.stretch[_direction(direction)]
    share = np.full(across + 1, width / across)
    share[[0, -1]] *= 0.5
    stress = expected * strain
    external = np.zeros_like(sim.positions)
    near, far = line(0), line(grid)
    external[near, axis] = -stress * share
    external[far, axis] = stress * share
    settle(sim, external=external)
    x = sim.positions
    measured_strain = (x[far, axis].mean() - x[near, axis].mean()) / length - 1.0
    measured = stress / measured_strain
    mid = x[line(grid // 2), 1 - axis]  # the strip's narrowing at its middle
    narrowing = (mid.max() - mid.min()) / width - 1.0
    return {
        "test": "tensile",
        "direction": direction,
        "grid": f"{grid}×{across}",
        "expected": expected,
        "measured": measured,
        "error": measured / expected - 1.0,
        "contraction": -narrowing / measured_strain,  # the Poisson's ratio the strip shows
    }


# ---------------------------------------------------------------------------- drape
#: the Cusick test's specimen and support radii (m): ISO 9073-9 / BS 5058
SPECIMEN_RADIUS = 0.15
SUPPORT_RADIUS = 0.09


def disc(
    fabric,
    grid: int,
    radius: float = SPECIMEN_RADIUS,
    support: float = SUPPORT_RADIUS,
    height: float = 0.0,
) -> ClothModel:
    """A disc of ``radius`` cut from a ``grid × grid`` square of the fabric (its particles within
    the radius, the springs, triangles and bending stencils among them), the particles within
    ``support`` pinned, at ``z = height``."""
    n = grid + 1
    r, c = np.divmod(np.arange(n * n), n)
    at = np.stack([c, r], axis=1) * (2 * radius / grid) - radius
    held = np.linalg.norm(at, axis=1) <= support + 1e-12
    full = ClothModel.grid(
        rows=n,
        cols=n,
        size=(2 * radius, 2 * radius),
        material=fabric,
        origin=(-radius, -radius, height),
        pinned=[(int(a), int(b)) for a, b in zip(r[held], c[held])],
    )
    return cut(full, np.linalg.norm(full.positions[:, :2], axis=1) <= radius + 1e-12)


def cut(model: ClothModel, keep: np.ndarray, pinned=None) -> ClothModel:
    """The part of ``model`` on the particles ``keep`` (bool): springs, triangles and bending
    stencils wholly inside it; ``pinned(x)`` marks the new pins (default: the old ones)."""

    new = np.full(model.n_particles, -1, np.int64)
    new[keep] = np.arange(int(keep.sum()))
    s_ok = keep[model.springs].all(axis=1)
    t_ok = keep[model.triangles].all(axis=1)
    x = model.positions[keep]
    bending = None
    if model.bending is not None:
        b = model.bending
        b_ok = keep[b.stencils].all(axis=1)
        bending = Bending(new[b.stencils[b_ok]], b.weights[b_ok], b.rigidity[b_ok], len(x))
    pins = model.pinned[keep] if pinned is None else np.asarray(pinned(x), bool)
    return ClothModel(
        positions=x,
        masses=model.masses[keep],
        springs=new[model.springs[s_ok]],
        rest_lengths=model.rest_lengths[s_ok],
        stiffness=model.stiffness[s_ok],
        damping=model.damping[s_ok],
        family=model.family[s_ok],
        family_names=model.family_names,
        kind=model.kind[s_ok],
        strain_limited=model.strain_limited[s_ok],
        pinned=pins,
        triangles=new[model.triangles[t_ok]],
        model=model.model,
        spacing=model.spacing,
        meta=dict(model.meta),
        bending=bending,
    )


@numba.njit(cache=True)
def _raster(p, tris, lo, pixel, image):
    """Mark the pixels whose centres lie in any triangle of the projection ``p`` (n, 2)."""
    n = image.shape[0]
    for t in range(tris.shape[0]):
        a, b, c = tris[t, 0], tris[t, 1], tris[t, 2]
        ax, ay, bx, by, cx, cy = p[a, 0], p[a, 1], p[b, 0], p[b, 1], p[c, 0], p[c, 1]
        den = (by - cy) * (ax - cx) + (cx - bx) * (ay - cy)
        if abs(den) < 1e-300:
            continue
        i0 = max(int((min(ax, bx, cx) - lo) / pixel), 0)
        i1 = min(int((max(ax, bx, cx) - lo) / pixel) + 1, n - 1)
        j0 = max(int((min(ay, by, cy) - lo) / pixel), 0)
        j1 = min(int((max(ay, by, cy) - lo) / pixel) + 1, n - 1)
        for i in range(i0, i1 + 1):
            px = lo + (i + 0.5) * pixel
            for j in range(j0, j1 + 1):
                py = lo + (j + 0.5) * pixel
                w0 = ((by - cy) * (px - cx) + (cx - bx) * (py - cy)) / den
                w1 = ((cy - ay) * (px - cx) + (ax - cx) * (py - cy)) / den
                if w0 >= 0.0 and w1 >= 0.0 and w0 + w1 <= 1.0:
                    image[i, j] = 1


def shadow_area(
    positions: np.ndarray, triangles: np.ndarray, half: float, pixels: int = 2048
) -> float:
    """The area of the cloth's vertical projection (its shadow under a light overhead), m², by
    rasterising its triangles over ``[−half, half]²``."""
    image = np.zeros((pixels, pixels), np.uint8)
    pixel = 2.0 * half / pixels
    _raster(
        np.ascontiguousarray(positions[:, :2]),
        np.ascontiguousarray(triangles),
        -half,
        pixel,
        image,
    )
    return float(image.sum()) * pixel * pixel


def drape(
    material,
    grid: int = 64,
    seconds: float = 6.0,
    rest_speed: float = REST_SPEED,
    method: str = "explicit",
) -> dict:
    """The virtual Cusick drape test: the disc (:func:`disc`) released flat over its support and
    simulated by ``method`` (:data:`DRAPE_METHODS`: symplectic Euler at 0.9 of its stable step, or
    ``vbd`` at 1/60 s with its defaults), with air drag of relaxation time 0.1 s at every
    resolution, until no particle moves faster than ``rest_speed`` (m/s, checked every 0.25 s) or
    ``seconds`` have passed; the drape coefficient of its shadow.

    (Why explicit by default: it is the cheaper converged method here. The specimen's cells are
    millimetres, so its vertices' inertia is tiny beside a real fabric's springs; ``vbd`` solves
    such steps directly (:mod:`~cloth_sim.integrators.vbd_newton`) or by many sweeps, at 1.0–4.1×
    the explicit wall time for cotton and denim at 16–64 cells, with the same coefficient at 64
    (0.3252, 0.4468). At 16 and 32 cells the folds can differ with the path: cotton at 16 drapes
    to 0.3253 on ``vbd`` and 0.2116 explicitly. ``cloth-sim textile drape --method vbd``.)"""
    fabric = resolve(material)
    if int(grid) != grid or grid < 8:
        raise ValueError(
            f"grid: expected an integer >= 8 (cells across the specimen), got {grid!r}"
        )
    if method not in DRAPE_METHODS:
        raise ValueError(f"method: expected one of {', '.join(DRAPE_METHODS)}, got {method!r}")
    model = disc(fabric, int(grid))
    if method == "vbd":
        sim = released(model, "vbd", 1.0 / 60)
    else:
        sim = released(model, "symplectic_euler", 1e-6)
        sim.dt = 0.9 * sim.stable_dt()
    until_rest(sim, seconds, rest_speed)
    area = shadow_area(sim.positions, model.triangles, SPECIMEN_RADIUS * 1.05)
    a_spec = math.pi * SPECIMEN_RADIUS**2
    a_sup = math.pi * SUPPORT_RADIUS**2
    return {
        "test": "drape",
        "method": method,
        "grid": f"{grid}×{grid}",
        "drape_coefficient": (area - a_sup) / (a_spec - a_sup),
        "bending_length": fabric.bending_length(0),
        "settled_at": sim.time,
        "speed_at_end": float(np.abs(sim.velocities).max()),
        "positions": sim.positions.copy(),
        "triangles": model.triangles,
    }


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
