"""Rigid colliders the cloth rests on, drapes over and is dragged by: plane, sphere, box, capsule,
cylinder and triangle mesh.

A collider is a shape with a pose and Coulomb friction ``μ`` (static = kinetic). The cloth keeps at
least the simulator's ``thickness`` from every collider surface. Colliders are kinematic: the
simulation never moves them, :meth:`cloth_sim.simulator.Simulator.set_collider_pose` does, and a
moved collider's velocity is its pose change over the next step (so friction drags what rests on
it).

Poses. ``orientation`` is a unit quaternion ``(w, x, y, z)``. A Box's ``orientation`` is absolute
(its half extents are along its own axes); a Plane's and a Capsule's orientation is relative to the
normal and segment they were built with, so ``set_collider_pose(i, position)`` with the default
orientation moves them without turning them. The pose's ``position`` is a Sphere's or Box's centre,
a Capsule's midpoint, and for a Plane a point on it (it starts at ``offset·normal``). A Cylinder's
and a Mesh's pose are absolute, as a Box's (the cylinder's axis is its own z, as URDF's; a mesh's
vertices are in its own frame).

Contact response: :class:`Contacts`, a post-step stage (see
:mod:`cloth_sim.constraints.strain_limit`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import ConvexHull, QhullError
from scipy.spatial.transform import Rotation

from ..physics.mesh import check_indices, read_mesh
from . import triangle_meshes
from .collider_kernels import (
    BOX,
    CAPSULE,
    CYLINDER,
    MESH,
    PLANE,
    SPHERE,
    ContactResults,
    PackedColliders,
    distances,
    resolve_contacts,
)
from .geometry import (
    matrix_quaternion,
    positive,
    quaternion_matrix,
    read_only,
    unit_quaternion,
    vector,
)
from .triangle_meshes import TriangleMesh

#: a particle within this fraction of a thickness above a collider's skin is *supported* by it:
#: self-collision moves it as if held (when both sides of a pair are, the one farther from the
#: collider moves), so that cloth landing on cloth that lies on a collider does not drive it into
#: the collider (when only touching particles were held, a T-shirt's lower layer was pushed 20 %
#: into a table's 4 mm skin: particles a hair above the skin were free). Below 1, so a second layer
#: resting on the first (2h up) is free.
SUPPORT = 0.5


def _friction(value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"friction must be a finite number >= 0, got {value!r}") from None
    if not (math.isfinite(v) and v >= 0):
        raise ValueError(f"friction must be a finite number >= 0, got {value!r}")
    return v


def check_new(collider, colliders) -> None:
    """``collider`` may join ``colliders``: a shape of this module whose name none of them has;
    ``ValueError`` naming what is wrong otherwise."""
    if not isinstance(collider, Collider):
        raise ValueError(
            f"a collider must be a cloth_sim.contact.colliders shape (Plane, Sphere, Box, "
            f"Capsule, Cylinder, Mesh), got {type(collider).__name__}"
        )
    if any(c.name == collider.name for c in colliders):
        raise ValueError(
            f"a collider named {collider.name!r} exists already; colliders: "
            f"{', '.join(c.name for c in colliders)}"
        )


def check_index(i, count: int, doing: str) -> None:
    """``i`` indexes one of ``count`` colliders (negative from the end), or ``ValueError``
    saying the range (or that there is none to ``doing``)."""
    if isinstance(i, bool) or not isinstance(i, (int, np.integer)) or not -count <= i < count:
        raise ValueError(
            f"collider index must be an integer in [0, {count - 1}], got {i!r}"
            if count
            else f"there are no colliders to {doing}"
        )


def hull_corners(points: np.ndarray) -> np.ndarray:
    """The corners of ``points``' convex hull (qhull, :class:`scipy.spatial.ConvexHull`); all
    the points where they span no solid (qhull needs one)."""
    try:
        return points[ConvexHull(points).vertices]
    except QhullError:
        return points


class Collider:
    """Base class: ``kind``, ``friction``, ``name``, a pose (``position``, ``rotation``) and the
    shape's local parameters ``geometry`` (4 numbers)."""

    kind = -1
    #: the triangle mesh of a Mesh collider (``None`` for the analytic shapes)
    mesh = None

    def __init__(self, position, geometry, friction, name, orientation=(1.0, 0.0, 0.0, 0.0)):
        self.set_pose(position, orientation)
        self.geometry = np.array(geometry, dtype=np.float64)
        self.friction = _friction(friction)
        self.name = str(name) if name is not None else type(self).__name__.lower()

    def set_pose(self, position, orientation=(1.0, 0.0, 0.0, 0.0)) -> None:
        """Place the collider (see the module docstring for what ``position`` and ``orientation``
        mean for each shape)."""
        p = vector("position", position)
        q = unit_quaternion(orientation)
        #: the pose: ``position``, the unit quaternion ``orientation`` (w, x, y, z) and its matrix
        self.position, self.orientation, self.rotation = p, q, quaternion_matrix(q)

    def place(self, transform: np.ndarray) -> None:
        """Place the collider at a rigid ``transform`` (4×4) computed by the package itself (a
        robot link's forward kinematics): :meth:`set_pose` without its checks."""
        self.position = np.ascontiguousarray(transform[:3, 3], dtype=np.float64)
        self.rotation = np.ascontiguousarray(transform[:3, :3], dtype=np.float64)
        self.orientation = matrix_quaternion(self.rotation)

    @property
    def reach(self) -> float:
        """How far from its position any point of the shape is (``inf``: unbounded)."""
        g = self.geometry
        if self.kind == SPHERE:
            return float(g[0])
        if self.kind == BOX:
            return float(np.linalg.norm(g[:3]))
        if self.kind == CAPSULE:
            return float(np.linalg.norm(g[:3]) + g[3])
        if self.kind == CYLINDER:
            return float(math.hypot(g[0], g[1]))
        if self.kind == MESH:
            return self.mesh.extent
        return math.inf

    @property
    def hull(self) -> tuple[np.ndarray, float] | None:
        """Points in the shape's own frame and a radius: the shape lies within that radius of
        their convex hull (None: a half-space, unbounded). A rigid motion moves no point of the
        shape farther than it moves the farthest of those points plus the radius times the chord
        its turn sweeps (:meth:`Contacts.travels`)."""
        g = self.geometry
        if self.kind == SPHERE:
            return np.zeros((1, 3)), float(g[0])
        if self.kind == BOX:
            signs = np.array([[a, b, c] for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)])
            return signs * g[:3], 0.0
        if self.kind == CAPSULE:
            return np.array([-g[:3], g[:3]]), float(g[3])
        if self.kind == CYLINDER:  # (within its radius of its axis)
            return np.array([[0.0, 0.0, -g[1]], [0.0, 0.0, g[1]]]), float(g[0])
        if self.kind == MESH:  # (its hull's corners: the farthest move is at one of them)
            return hull_corners(self.mesh.vertices), 0.0
        return None

    def signed_distance(self, points) -> np.ndarray:
        """Signed distance of ``(k, 3)`` points from the surface (negative inside)."""
        pts = read_only(np.reshape(points, (-1, 3)), np.float64)
        pos = np.reshape(np.asarray(self.position, np.float64), (1, 3))
        rot = np.reshape(np.asarray(self.rotation, np.float64), (1, 3, 3))
        geo = np.reshape(np.asarray(self.geometry, np.float64), (1, 4))
        return distances(self.kind, pos, rot, geo, pts, self._bank)

    #: the bank :meth:`signed_distance` reads (a Mesh's own mesh at index 0)
    _bank = triangle_meshes.EMPTY

    def __repr__(self):
        return f"{type(self).__name__}(name={self.name!r}, position={self.position.tolist()})"


class Plane(Collider):
    """The half-space boundary ``{x : normal·x = offset}``; the cloth lives where ``normal·x >
    offset``."""

    kind = PLANE

    def __init__(
        self, normal=(0.0, 0.0, 1.0), offset: float = 0.0, friction: float = 0.0, name=None
    ):
        n = vector("normal", normal)
        norm = float(np.linalg.norm(n))
        if not norm > 1e-12:
            raise ValueError(f"normal must be a nonzero vector, got {n.tolist()}")
        n = n / norm
        try:
            offset = float(offset)
        except (TypeError, ValueError):
            raise ValueError(f"offset must be a finite number, got {offset!r}") from None
        if not math.isfinite(offset):
            raise ValueError(f"offset must be a finite number, got {offset!r}")
        super().__init__(offset * n, [n[0], n[1], n[2], 0.0], friction, name)

    @property
    def normal(self) -> np.ndarray:
        return self.rotation @ self.geometry[:3]

    @property
    def offset(self) -> float:
        return float(self.normal @ self.position)


class Sphere(Collider):
    """A solid ball."""

    kind = SPHERE

    def __init__(
        self, center=(0.0, 0.0, 0.0), radius: float = 0.1, friction: float = 0.0, name=None
    ):
        super().__init__(
            vector("center", center), [positive("radius", radius), 0, 0, 0], friction, name
        )

    @property
    def center(self) -> np.ndarray:
        return self.position.copy()

    @property
    def radius(self) -> float:
        return float(self.geometry[0])


class Box(Collider):
    """A solid oriented box: ``center``, ``half_extents`` along its own axes, ``orientation``."""

    kind = BOX

    def __init__(
        self,
        center=(0.0, 0.0, 0.0),
        half_extents=(0.5, 0.5, 0.5),
        orientation=(1.0, 0.0, 0.0, 0.0),
        friction: float = 0.0,
        name=None,
    ):
        h = vector("half_extents", half_extents)
        if not np.all(h > 0):
            raise ValueError(f"half_extents must be 3 finite numbers > 0, got {h.tolist()}")
        super().__init__(
            vector("center", center), [h[0], h[1], h[2], 0.0], friction, name, orientation
        )

    @property
    def center(self) -> np.ndarray:
        return self.position.copy()

    @property
    def half_extents(self) -> np.ndarray:
        return self.geometry[:3].copy()


class Capsule(Collider):
    """A solid capsule: the points within ``radius`` of the segment ``a``–``b``."""

    kind = CAPSULE

    def __init__(
        self,
        a=(0.0, 0.0, 0.0),
        b=(0.0, 0.0, 1.0),
        radius: float = 0.05,
        friction: float = 0.0,
        name=None,
    ):
        a, b = vector("a", a), vector("b", b)
        half = 0.5 * (b - a)
        super().__init__(
            0.5 * (a + b), [half[0], half[1], half[2], positive("radius", radius)], friction, name
        )

    @property
    def a(self) -> np.ndarray:
        return self.position - self.rotation @ self.geometry[:3]

    @property
    def b(self) -> np.ndarray:
        return self.position + self.rotation @ self.geometry[:3]

    @property
    def radius(self) -> float:
        return float(self.geometry[3])


class Cylinder(Collider):
    """A solid cylinder: ``radius``, ``length`` along its own z axis (as URDF's ``<cylinder>``),
    centred at ``center``, turned by ``orientation``."""

    kind = CYLINDER

    def __init__(
        self,
        center=(0.0, 0.0, 0.0),
        radius: float = 0.05,
        length: float = 0.2,
        orientation=(1.0, 0.0, 0.0, 0.0),
        friction: float = 0.0,
        name=None,
    ):
        r, h = positive("radius", radius), positive("length", length)
        super().__init__(vector("center", center), [r, 0.5 * h, 0, 0], friction, name, orientation)

    @property
    def center(self) -> np.ndarray:
        return self.position.copy()

    @property
    def radius(self) -> float:
        return float(self.geometry[0])

    @property
    def length(self) -> float:
        return float(2.0 * self.geometry[1])


class Mesh(Collider):
    """A rigid triangle mesh, a solid where it is closed and two-sided where it is open
    (:mod:`.triangle_meshes`): ``source`` a mesh file (the formats
    :meth:`cloth_sim.model.ClothModel.from_mesh` reads: OBJ, PLY, STL, glTF/GLB, OFF) or a
    ``(vertices (n, 3), faces (t, 3))`` pair, in its own frame times ``scale`` (metres per unit, a
    number or one per axis, as URDF's ``<mesh scale>``); placed at ``position``, turned by
    ``orientation``."""

    kind = MESH

    def __init__(
        self,
        source,
        position=(0.0, 0.0, 0.0),
        orientation=(1.0, 0.0, 0.0, 0.0),
        scale=1.0,
        friction: float = 0.0,
        name=None,
    ):

        factors = np.atleast_1d(np.asarray(scale, dtype=np.float64)) if _numbers(scale) else None
        if (
            factors is None
            or factors.shape not in ((1,), (3,))
            or not np.all(np.isfinite(factors) & (factors > 0))
        ):
            raise ValueError(
                f"Mesh: scale must be a finite number > 0 or 3 of them (metres per unit along "
                f"x, y, z), got {scale!r}"
            )
        vertices, faces, where = read_mesh(source)
        check_indices(vertices, faces, where)
        self.source = where
        self.mesh = TriangleMesh(vertices * factors, faces, where)
        self._bank = triangle_meshes.pack([self.mesh])  # (geometry[0] = 0: its index there)
        super().__init__(vector("position", position), [0, 0, 0, 0], friction, name, orientation)

    @property
    def vertices(self) -> np.ndarray:
        """The mesh's vertices in the world, at its current pose."""
        return self.mesh.vertices @ self.rotation.T + self.position

    @property
    def triangles(self) -> np.ndarray:
        return self.mesh.triangles


def _numbers(value) -> bool:
    try:
        np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return False
    return not isinstance(value, (bool, str))


KINDS = {
    "plane": Plane,
    "sphere": Sphere,
    "box": Box,
    "capsule": Capsule,
    "cylinder": Cylinder,
    "mesh": Mesh,
}


# ---------------------------------------------------------------------------- kernels


class Contacts:
    """The post-step stage that keeps the cloth ``thickness`` away from its colliders (see
    :func:`resolve_contacts` for the method). Active when there is at least one collider.

    It works with every integrator because it acts on the step's result: positions are projected
    and the velocity is filtered after the step, as a collision impulse applied at its end
    (explicit and Runge–Kutta methods, the implicit ones, whose solve does not see the contacts,
    and Verlet, whose next step reads the corrected positions as its velocity). Friction acts on
    both the position change and the velocity, so a particle on an incline under static friction
    does not creep, and a sliding one accelerates by ``g (sin θ − μ cos θ)``.
    """

    name = "contacts"
    #: whether the paths over the step are checked (1): off where the integrator kept them out
    #: of the colliders inside its own step (``vbd``, whose conservative bound does: checked
    #: again here from the carried start, against the swept links, the stage's stops pushed the
    #: cloth through its own other layers, 188 crossings in robot_sweep's 4.6 s against vbd's 3)
    continuous = True

    def __init__(self, model, colliders=(), thickness: float = 0.005):
        self.model = model
        self.colliders = list(colliders)
        for i, c in enumerate(self.colliders):
            if not isinstance(c, Collider):
                raise ValueError(
                    f"colliders[{i}] must be a cloth_sim.contact.colliders shape (Plane, Sphere, "
                    f"Box, Capsule, Cylinder, Mesh), got {type(c).__name__}"
                )
        self.thickness = positive("thickness", thickness)
        self.touching = np.zeros(model.n_particles, dtype=np.bool_)
        #: per particle, the distance above the nearest collider's skin after the last step (inf:
        #: none)
        self.clearance = np.full(model.n_particles, np.inf)
        self.last_touching = 0
        # read-only whoever owns them: the kernel is compiled for one signature
        self._pinned = read_only(model.pinned, np.bool_)
        self._masses = read_only(model.masses, np.float64)
        self._push = np.zeros((0, 3))  # the impulses of the last step, per collider
        self._turn = np.zeros((0, 3))
        self._pack()
        self._pos0, self._rot0 = self._pos.copy(), self._rot.copy()

    def _pack(self):
        cs = self.colliders
        self._packed = list(cs)
        self._kinds = np.array([c.kind for c in cs], dtype=np.int64)
        self._pos = np.array([c.position for c in cs], dtype=np.float64).reshape(-1, 3)
        self._rot = np.array([c.rotation for c in cs], dtype=np.float64).reshape(-1, 3, 3)
        self._geo = np.array([c.geometry for c in cs], dtype=np.float64).reshape(-1, 4)
        self._mu = np.array([c.friction for c in cs], dtype=np.float64)
        self._reach = np.array([c.reach for c in cs], dtype=np.float64)
        self._hulls = [c.hull for c in cs]
        # the meshes packed for the kernels, each Mesh's row naming its index in the bank
        meshes = [c.mesh for c in cs if c.mesh is not None]
        self._bank = triangle_meshes.pack(meshes) if meshes else triangle_meshes.EMPTY
        self._geo[self._kinds == MESH, 0] = np.arange(len(meshes))

    @property
    def active(self) -> bool:
        return len(self.colliders) > 0

    def set_pinned(self, pinned) -> None:
        """Particles the stage leaves alone (pins and held particles)."""
        self._pinned = read_only(pinned, np.bool_)

    def add(self, collider) -> int:
        """Append a collider (its pose now is where its first step starts); returns its index."""
        check_new(collider, self.colliders)
        self.colliders.append(collider)
        self._repack()
        return len(self.colliders) - 1

    def remove(self, i: int):
        """Remove collider ``i``; returns it."""
        check_index(i, len(self.colliders), "remove")
        c = self.colliders.pop(i)
        self._repack()
        return c

    def _repack(self) -> None:
        """The packed arrays again after the list changed; the others keep their step-start
        poses."""
        starts = {id(c): (p, r) for c, p, r in zip(self._packed, self._pos0, self._rot0)}
        self._pack()
        self._pos0, self._rot0 = self._pos.copy(), self._rot.copy()
        for k, c in enumerate(self.colliders):
            if id(c) in starts:
                self._pos0[k], self._rot0[k] = starts[id(c)]

    def _index(self, i, doing: str) -> None:
        check_index(i, len(self.colliders), doing)

    def place(self, placements, teleport: bool = False) -> None:
        """Several colliders at once, ``[(collider, 4×4 transform)]``, from the package's own
        kinematics (no checks: :meth:`Collider.place`); as :meth:`set_pose` otherwise."""
        index = {id(c): i for i, c in enumerate(self.colliders)}
        for collider, transform in placements:
            i = index[id(collider)]
            collider.place(transform)
            self._pos[i] = collider.position
            self._rot[i] = collider.rotation
            if teleport:
                self._pos0[i] = self._pos[i]
                self._rot0[i] = self._rot[i]

    def set_pose(
        self, i: int, position, orientation=(1.0, 0.0, 0.0, 0.0), teleport: bool = False
    ) -> None:
        """Collider ``i``'s pose at the end of the next step (it sweeps there from where it is),
        or, with ``teleport``, at its start too (it stands there)."""
        self._index(i, "move")
        self.colliders[i].set_pose(position, orientation)
        self._pos[i] = self.colliders[i].position
        self._rot[i] = self.colliders[i].rotation
        if teleport:
            self._pos0[i] = self._pos[i]
            self._rot0[i] = self._rot[i]

    def wrench(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """``(force, torque)`` the cloth exerted on collider ``i`` over the last step (N, N·m,
        world frame, torque about its position): the impulses the contact stage's velocity filter
        took from the particles touching it, over ``dt``. (Where a method resolves the contacts
        inside its own step, ``vbd``, the stage only finishes them and this misses their
        force.)"""
        self._index(i, "read")
        if i >= len(self._push):  # added since the last step
            return np.zeros(3), np.zeros(3)
        return self._push[i] / self._dt, self._turn[i] / self._dt

    _dt = 1.0

    def apply(self, state, start, dt, velocity_follow, origin=None):
        if self._push.shape[0] != len(self.colliders):
            self._push = np.zeros((len(self.colliders), 3))
            self._turn = np.zeros((len(self.colliders), 3))
        self._push[:] = 0.0
        self._turn[:] = 0.0
        self._dt = dt
        self.last_touching = resolve_contacts(
            state.x,
            state.v,
            start.x,
            self._pinned,
            self._masses,
            self.packed(),
            self.thickness,
            dt,
            self.continuous,
            ContactResults(self.touching, self.clearance, self._push, self._turn),
        )
        self.end_step()

    def end_step(self) -> None:
        """The poses this step ended at are where the next one starts."""
        np.copyto(self._pos0, self._pos)
        np.copyto(self._rot0, self._rot)

    def travels(self, packed: PackedColliders) -> np.ndarray:
        """How far any point of each collider moves over ``packed``'s step (its poses there, in
        this stage's order, as :meth:`packed` and :func:`packed_parts` give them): the farthest
        move of the points of its :attr:`Collider.hull`, ``|Δpos + ΔR·q|`` (exact for a box or a
        mesh: the move is affine in the point, so its largest over a convex hull is at a corner),
        plus the hull's radius times the chord the turn sweeps, ``‖ΔR‖/√2`` (Frobenius, a
        rotation's); a half-space's shift."""
        out = np.zeros(len(self._hulls))
        for i, hull in enumerate(self._hulls):
            shift = packed.pos[i] - packed.pos0[i]
            turn = packed.rot[i] - packed.rot0[i]
            if not (shift.any() or turn.any()):
                continue  # (a still one, however many corners it has)
            if hull is None:
                out[i] = np.linalg.norm(shift)
                continue
            points, radius = hull
            moves = shift + points @ turn.T
            farthest = np.sqrt(np.einsum("ij,ij->i", moves, moves).max())
            out[i] = farthest + radius * np.linalg.norm(turn) / math.sqrt(2.0)
        return out

    def packed(self) -> PackedColliders:
        """The colliders as the contact kernels read them (an integrator that resolves contacts
        inside its step reads them here)."""
        return PackedColliders(
            self._kinds,
            self._pos,
            self._rot,
            self._pos0,
            self._rot0,
            self._geo,
            self._mu,
            self._reach,
            *self._bank,
        )


def packed_parts(packed: PackedColliders, n: int) -> list[PackedColliders]:
    """:meth:`Contacts.packed` over each of the ``n`` equal parts of the step (an integrator that
    steps the step's motion in parts): part ``k`` starts at each collider's pose at ``k/n`` and
    ends at its pose at ``(k+1)/n`` (the same arrays as the next part's start), its position
    interpolated linearly and its rotation by spherical interpolation between the step's two
    poses, ``R0·exp(s·log(R0ᵀR1))`` (scipy's :class:`~scipy.spatial.transform.Slerp`, for all
    the colliders at once)."""
    kinds, pos, rot, pos0, rot0 = packed.kinds, packed.pos, packed.rot, packed.pos0, packed.rot0
    if n == 1 or not len(kinds):
        return [packed] * n
    start = Rotation.from_matrix(rot0)
    turn = (start.inv() * Rotation.from_matrix(rot)).as_rotvec()
    poses = [(pos0, rot0)]
    for k in range(1, n):
        s = k / n
        p = np.ascontiguousarray(pos0 + s * (pos - pos0))
        poses.append((p, (start * Rotation.from_rotvec(turn * s)).as_matrix()))
    poses.append((pos, rot))
    return [
        packed._replace(pos=e[0], rot=e[1], pos0=b[0], rot0=b[1])
        for b, e in zip(poses[:-1], poses[1:])
    ]
