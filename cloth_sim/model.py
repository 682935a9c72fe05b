"""The cloth's topology and material: particles, masses, pins and spring families.

A :class:`ClothModel` is read-only once built. Integrators never touch it: they advance a state
(positions, velocities) that a :class:`~cloth_sim.simulator.Simulator` owns, so several simulators
can share one model.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .constraints.grippers import check_pose
from .kinds import (  # noqa: F401 (the model's vocabulary, importable from here too)
    BUCKLING,
    GRID_FAMILIES,
    LINEAR,
    MESH_FAMILIES,
    MODELS,
    ORIENTATIONS,
    SPRING_FAMILY,
    STRAIN_LIMIT_METHODS,
    TENSION_ONLY,
)
from .materials import resolve
from .materials.discretize import grid_material, mesh_material
from .parameters import SCHEMA, ParameterError
from .physics import mesh as M


def _freeze(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class ClothModel:
    """Particles joined by springs, grouped in named families.

    Attributes (all read-only arrays):
        positions: ``(n, 3)`` float64 initial positions.
        masses: ``(n,)`` float64 particle masses (kg).
        springs: ``(m, 2)`` int64 particle indices.
        rest_lengths: ``(m,)`` float64.
        stiffness, damping: ``(m,)`` float64 per spring (N/m, N·s/m).
        family: ``(m,)`` int64 index into ``family_names``.
        kind: ``(m,)`` int8, one of :data:`LINEAR`, :data:`TENSION_ONLY`, :data:`BUCKLING`.
        strain_limited: ``(m,)`` bool, springs that Provot's correction shortens.
        pinned: ``(n,)`` bool.
        triangles: ``(t, 3)`` int64 surface triangles (for normals and wind), possibly empty.
        rows, cols: grid shape, or ``None`` for a general spring network.
        bending: a material's bending energy (:class:`~cloth_sim.physics.bending.Bending`).
        meta: ``material`` (the fabric a model was built from), ``size``; a mesh's landmarks.
    """

    positions: np.ndarray
    masses: np.ndarray
    springs: np.ndarray
    rest_lengths: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    family: np.ndarray
    family_names: tuple[str, ...]
    kind: np.ndarray
    strain_limited: np.ndarray
    pinned: np.ndarray
    triangles: np.ndarray
    rows: int | None = None
    cols: int | None = None
    model: str = "provot"
    spacing: float | None = None
    meta: dict = field(default_factory=dict)
    bending: object | None = None  # a physics.bending.Bending (a material's flexural rigidity)

    def __post_init__(self):
        n, m = len(self.masses), len(self.springs)
        checks = [
            (self.positions.shape == (n, 3), "positions must be (n, 3)"),
            (self.springs.shape == (m, 2), "springs must be (m, 2)"),
            (self.rest_lengths.shape == (m,), "rest_lengths must be (m,)"),
            (self.stiffness.shape == (m,), "stiffness must be (m,)"),
            (self.damping.shape == (m,), "damping must be (m,)"),
            (self.pinned.shape == (n,), "pinned must be (n,)"),
        ]
        for ok, msg in checks:
            if not ok:
                raise ValueError(msg)
        if m and (self.springs.min() < 0 or self.springs.max() >= n):
            raise ValueError(f"springs: particle indices must lie in [0, {n - 1}]")
        if m and np.any(self.springs[:, 0] == self.springs[:, 1]):
            raise ValueError("springs: a spring must join two different particles")
        if self.bending is not None and self.bending.n != n:
            raise ValueError("bending: its particle count differs from the model's")
        if not np.all(np.isfinite(self.positions)):
            raise ValueError("positions must be finite")
        if np.any(~np.isfinite(self.masses)) or np.any(self.masses <= 0):
            raise ValueError("masses must be finite and > 0")
        for name in ("stiffness", "damping"):
            a = getattr(self, name)
            if np.any(~np.isfinite(a)) or np.any(a < 0):
                raise ValueError(f"{name} must be finite and >= 0")
        if np.any(~np.isfinite(self.rest_lengths)) or np.any(self.rest_lengths <= 0):
            raise ValueError("rest_lengths must be finite and > 0")
        for name in (
            "positions",
            "masses",
            "springs",
            "rest_lengths",
            "stiffness",
            "damping",
            "family",
            "kind",
            "strain_limited",
            "pinned",
            "triangles",
        ):
            object.__setattr__(self, name, _freeze(getattr(self, name)))

    # ------------------------------------------------------------------ builders
    @classmethod
    def grid(
        cls,
        rows: int,
        cols: int,
        spacing: float | None = None,
        particle_mass: float | None = None,
        stiffness: dict | float | None = None,
        damping: dict | float | None = None,
        pinned=(),
        model: str = "provot",
        orientation: str = "horizontal",
        origin=(0.0, 0.0, 0.0),
        size=None,
        material=None,
    ) -> "ClothModel":
        """A regular ``rows × cols`` grid after Provot (1995), or Choi & Ko (2002) with
        ``model="choi_ko"``.

        Springs: structural ``[i,j]–[i+1,j]``, ``[i,j]–[i,j+1]``; shear ``[i,j]–[i+1,j+1]``,
        ``[i+1,j]–[i,j+1]``; bend ``[i,j]–[i+2,j]``, ``[i,j]–[i,j+2]`` and, for ``choi_ko``, also
        ``[i,j]–[i+2,j+2]``, ``[i+2,j]–[i,j+2]``. Particle ``(row, col)`` has index ``row*cols +
        col`` and starts at ``(col·s, row·s, 0)`` (``horizontal``) or ``(col·s, 0, −row·s)``
        (``vertical``, row 0 on top), plus ``origin`` (the position of particle ``(0, 0)``).

        In ``choi_ko`` the structural and shear springs resist stretching only (type 1) and the
        bend springs follow the immediate-buckling model (type 2), whose compressed branch reads
        the bend stiffness as the flexural rigidity ``k_b`` (see :mod:`cloth_sim.physics.forces`).

        ``stiffness`` and ``damping`` are dicts keyed by family (missing families get 0) or one
        number for all. ``pinned`` lists ``(row, col)`` pairs; negative indices count from the end.

        ``size=(width, height)`` (m) sets the spacing instead: ``width/(cols − 1)`` along columns,
        ``height/(rows − 1)`` along rows. ``material`` (a :class:`~cloth_sim.materials.Fabric`,
        a library name or a mapping of its fields) with ``size`` replaces ``particle_mass``,
        ``stiffness`` and ``damping``: :mod:`cloth_sim.materials.discretize` maps the fabric onto
        the grid (warp along +y, the row index), so the same fabric behaves the same at any
        ``rows``, ``cols``; its bending rigidity goes to :attr:`bending`.
        """

        try:
            rows, cols = SCHEMA["rows"].check(rows), SCHEMA["cols"].check(cols)
        except ParameterError as e:
            raise ValueError(f"grid: rows and cols: {e}") from None
        fabric = None
        if material is not None:
            fabric = resolve(material)
            if size is None:
                raise ValueError("grid: a material needs the cloth's size=(width, height) in m")
            given = [
                n
                for n, v in (
                    ("particle_mass", particle_mass),
                    ("stiffness", stiffness),
                    ("damping", damping),
                )
                if v is not None
            ]
            if given:
                raise ValueError(
                    f"grid: {', '.join(given)} and a material are both given: the material sets "
                    f"the masses, springs and damping"
                )
        if size is not None:
            ax, ay = _grid_size(size, rows, cols)
            spacing = min(ax, ay)
        else:
            spacing = SCHEMA["spacing"].check(spacing)
            ax = ay = spacing
        if fabric is None:
            if particle_mass is None or stiffness is None:
                raise ValueError(
                    "grid: give particle_mass and stiffness, or a material with the size"
                )
            particle_mass = SCHEMA["particle_mass"].check(particle_mass)
        if model not in MODELS:
            raise ValueError(f"grid: unknown model {model!r}; expected one of {', '.join(MODELS)}")
        if orientation not in ORIENTATIONS:
            raise ValueError(
                f"grid: unknown orientation {orientation!r}; expected one of "
                f"{', '.join(ORIENTATIONS)}"
            )
        if fabric is None:
            k_fam = _per_family("stiffness", stiffness)
            c_fam = _per_family("damping", damping if damping is not None else 0.0)

        idx = np.arange(rows * cols).reshape(rows, cols)
        pairs, fams = [], []

        def add(a, b, fam):
            pairs.append(np.stack([a.ravel(), b.ravel()], axis=1))
            fams.append(np.full(a.size, GRID_FAMILIES.index(fam)))

        add(idx[:-1, :], idx[1:, :], "structural")
        add(idx[:, :-1], idx[:, 1:], "structural")
        add(idx[:-1, :-1], idx[1:, 1:], "shear")
        add(idx[1:, :-1], idx[:-1, 1:], "shear")
        add(idx[:-2, :], idx[2:, :], "bend")
        add(idx[:, :-2], idx[:, 2:], "bend")
        if model == "choi_ko":
            add(idx[:-2, :-2], idx[2:, 2:], "bend")
            add(idx[2:, :-2], idx[:-2, 2:], "bend")
        springs = np.concatenate(pairs).astype(np.int64)
        family = np.concatenate(fams).astype(np.int64)

        r, c = np.divmod(np.arange(rows * cols), cols)
        if orientation == "horizontal":
            x = np.stack([c * ax, r * ay, np.zeros(r.size)], axis=1)
        else:
            x = np.stack([c * ax, np.zeros(r.size), -r * ay], axis=1)
        x = x.astype(np.float64)
        rest = np.linalg.norm(x[springs[:, 1]] - x[springs[:, 0]], axis=1)
        o = np.asarray(origin, dtype=np.float64)
        if o.shape != (3,) or not np.all(np.isfinite(o)):
            raise ValueError(f"grid: origin must be 3 finite numbers, got {origin!r}")
        x = x + o

        kind = np.full(len(springs), LINEAR, dtype=np.int8)
        if model == "choi_ko":
            kind[family != GRID_FAMILIES.index("bend")] = TENSION_ONLY
            kind[family == GRID_FAMILIES.index("bend")] = BUCKLING

        pin_mask = np.zeros(rows * cols, dtype=bool)
        for p in pinned:
            try:
                rr, cc = (int(v) for v in p)
            except (TypeError, ValueError):
                raise ValueError(
                    f"grid: pinned entries must be (row, col) pairs, got {p!r}"
                ) from None
            if not (-rows <= rr < rows and -cols <= cc < cols):
                raise ValueError(
                    f"grid: pinned (row, col) = {p!r} is outside the {rows}×{cols} grid"
                )
            pin_mask[(rr % rows) * cols + (cc % cols)] = True

        # two triangles per quad, consistently oriented
        a, b, cq, d = (
            idx[:-1, :-1].ravel(),
            idx[:-1, 1:].ravel(),
            idx[1:, 1:].ravel(),
            idx[1:, :-1].ravel(),
        )
        tris = np.concatenate([np.stack([a, b, cq], 1), np.stack([a, cq, d], 1)]).astype(np.int64)

        meta, bending = {}, None
        if fabric is not None:
            k, cdamp, masses, bending = grid_material(
                fabric, rows, cols, ax, ay, springs, family, GRID_FAMILIES, pin_mask
            )
            meta = {"material": fabric, "size": (ax * (cols - 1), ay * (rows - 1))}
        else:
            k = np.array([k_fam[f] for f in GRID_FAMILIES])[family]
            cdamp = np.array([c_fam[f] for f in GRID_FAMILIES])[family]
            masses = np.full(rows * cols, float(particle_mass))
            if size is not None:
                meta = {"size": (ax * (cols - 1), ay * (rows - 1))}
        return cls(
            positions=x,
            masses=masses,
            springs=springs,
            rest_lengths=rest,
            stiffness=k,
            damping=cdamp,
            family=family,
            family_names=GRID_FAMILIES,
            kind=kind,
            strain_limited=family != GRID_FAMILIES.index("bend"),
            pinned=pin_mask,
            triangles=tris,
            rows=rows,
            cols=cols,
            model=model,
            spacing=float(spacing),
            meta=meta,
            bending=bending,
        )

    @classmethod
    def from_springs(
        cls,
        positions,
        masses,
        springs,
        stiffness,
        damping=None,
        rest_lengths=None,
        pinned=None,
        triangles=None,
    ) -> "ClothModel":
        """Any spring network: ``positions (n,3)``, ``masses (n,)``, ``springs (m,2)``, per-spring
        ``stiffness (m,)`` and ``damping (m,)``, ``rest_lengths`` (default: the current lengths)
        and ``pinned`` particle indices. All springs are Hooke springs in one family, ``"spring"``,
        and all are strain-limited when the simulator has a strain limit. ``triangles (t,3)`` are
        optional; without them there are no normals and so no wind force."""
        x = np.array(positions, dtype=np.float64).reshape(-1, 3)
        n = len(x)
        s = np.array(springs, dtype=np.int64).reshape(-1, 2)
        m = len(s)
        k = np.broadcast_to(np.asarray(stiffness, dtype=np.float64), (m,)).copy()
        c = (
            np.zeros(m)
            if damping is None
            else np.broadcast_to(np.asarray(damping, dtype=np.float64), (m,)).copy()
        )
        mass = np.broadcast_to(np.asarray(masses, dtype=np.float64), (n,)).copy()
        if m and (s.min() < 0 or s.max() >= n):
            raise ValueError(f"springs: particle indices must lie in [0, {n - 1}]")
        if rest_lengths is None:
            rest = np.linalg.norm(x[s[:, 1]] - x[s[:, 0]], axis=1)
        else:
            rest = np.broadcast_to(np.asarray(rest_lengths, dtype=np.float64), (m,)).copy()
        pin_mask = np.zeros(n, dtype=bool)
        if pinned is not None:
            p = np.asarray(pinned, dtype=np.int64).ravel()
            if p.size and (p.min() < -n or p.max() >= n):
                raise ValueError(f"pinned: particle indices must lie in [0, {n - 1}]")
            pin_mask[p] = True
        tris = np.zeros((0, 3), np.int64) if triangles is None else np.asarray(triangles, np.int64)
        return cls(
            positions=x,
            masses=mass,
            springs=s,
            rest_lengths=rest,
            stiffness=k,
            damping=c,
            family=np.zeros(m, np.int64),
            family_names=(SPRING_FAMILY,),
            kind=np.full(m, LINEAR, np.int8),
            strain_limited=np.ones(m, bool),
            pinned=pin_mask,
            triangles=tris.reshape(-1, 3),
        )

    @classmethod
    def from_mesh(
        cls,
        source,
        density: float | None = None,
        stiffness: dict | float | None = None,
        damping: dict | float | None = None,
        pinned=(),
        model: str = "provot",
        scale: float = 1.0,
        position=(0.0, 0.0, 0.0),
        orientation=(1.0, 0.0, 0.0, 0.0),
        material=None,
    ) -> "ClothModel":
        """A cloth from any triangle mesh: ``source`` is a file (OBJ, PLY, STL, glTF/GLB, OFF; see
        :mod:`cloth_sim.physics.mesh`) or a ``(vertices, faces)`` pair.

        Springs: one ``structural`` per unique edge, one ``bend`` per interior edge joining the two
        vertices opposite it; rest lengths are the mesh's own, so a garment modelled curved rests
        curved. Masses: ``density`` (kg/m²) × a third of each adjacent triangle's area. Vertices at
        the same position are welded into one particle (a mesh without duplicates keeps its vertex
        order). ``model="choi_ko"``: structural springs resist stretching only and bend springs
        buckle (as on a grid). ``pinned`` lists vertex indices of the source (mapped through the
        welding). ``scale`` is metres per file unit; the scaled mesh is then rotated by
        ``orientation`` (a unit quaternion ``(w, x, y, z)``) and moved by ``position``.
        ``stiffness``/``damping``: dicts keyed by ``structural`` and ``bend``, or one number for
        both. A file's named vertices (:func:`cloth_sim.physics.mesh.read_landmarks`) are in
        ``meta["landmarks"]``, name → particle index.

        ``material`` (a :class:`~cloth_sim.materials.Fabric`, a library name or a mapping)
        replaces ``density``, ``stiffness`` and ``damping``: each edge's stiffness from its
        triangles' areas and the bending from the cotangent stencils
        (:func:`cloth_sim.materials.discretize.mesh_material`: isotropic, as a mesh here has no
        warp direction; the geometric mean of warp and weft).

        A mesh that cannot be cloth raises ``ValueError`` naming the source and the element (see
        :func:`cloth_sim.physics.mesh.check_mesh`); nothing is built."""

        fabric = None
        if material is not None:
            fabric = resolve(material)
            given = [
                n
                for n, v in (("density", density), ("stiffness", stiffness), ("damping", damping))
                if v is not None
            ]
            if given:
                raise ValueError(
                    f"from_mesh: {', '.join(given)} and a material are both given: the material "
                    f"sets the masses, springs and damping"
                )
            density = fabric.density
        elif density is None or stiffness is None:
            raise ValueError("from_mesh: give density and stiffness, or a material")
        vertices, faces, name = M.read_mesh(source, scale)
        density = SCHEMA["density"].check(density)
        if model not in MODELS:
            raise ValueError(
                f"from_mesh: unknown model {model!r}; expected one of {', '.join(MODELS)}"
            )
        if fabric is None:
            k_fam = _per_family("stiffness", stiffness, MESH_FAMILIES)
            c_fam = _per_family("damping", damping if damping is not None else 0.0, MESH_FAMILIES)
        try:
            pos, _, rot = check_pose(position, orientation)
        except ValueError as e:
            raise ValueError(f"from_mesh: {e}") from None
        M.check_indices(vertices, faces, name)  # before welding: indices and coordinates as given
        landmarks = M.read_landmarks(source, len(vertices))
        x, tris, index = M.weld(vertices, faces)
        M.check_mesh(x, tris, name)  # the rest after: welding can make a triangle degenerate or an
        # edge shared, and leaves no unused duplicate of a vertex
        x = x @ rot.T + pos
        structural, bend = M.mesh_springs(tris, len(x))
        springs = np.concatenate([structural, bend]).astype(np.int64)
        family = np.repeat(np.arange(2, dtype=np.int64), [len(structural), len(bend)])
        pin_mask = np.zeros(len(x), dtype=bool)
        p = np.asarray(list(pinned), dtype=np.float64).ravel()
        if p.size:
            if not np.all((p == np.round(p)) & (p >= 0) & (p < len(vertices))):
                raise ValueError(
                    f"from_mesh: pinned must be vertex indices in [0, {len(vertices) - 1}], "
                    f"got {list(pinned)[:8]!r}"
                )
            pin_mask[index[p.astype(np.int64)]] = True
        kind = np.full(len(springs), LINEAR, dtype=np.int8)
        if model == "choi_ko":
            kind[family == 0] = TENSION_ONLY
            kind[family == 1] = BUCKLING
        bending = None
        if fabric is not None:
            k, cdamp, bending = mesh_material(fabric, x, tris, springs, family)
        else:
            k = np.array([k_fam[f] for f in MESH_FAMILIES])[family]
            cdamp = np.array([c_fam[f] for f in MESH_FAMILIES])[family]
        return cls(
            positions=x,
            masses=M.lumped_masses(x, tris, density),
            springs=springs,
            rest_lengths=np.linalg.norm(x[springs[:, 1]] - x[springs[:, 0]], axis=1),
            stiffness=k,
            damping=cdamp,
            family=family,
            family_names=MESH_FAMILIES,
            kind=kind,
            strain_limited=family == 0,
            pinned=pin_mask,
            triangles=tris,
            model=model,
            meta={
                "source": name,
                "vertex_index": index,
                "density": density,
                # named vertices (a garment's collar, sleeve ends, …), as particle indices
                "landmarks": {k: int(index[i]) for k, i in landmarks.items()},
                **({"material": fabric} if fabric is not None else {}),
            },
            bending=bending,
        )

    # ------------------------------------------------------------------ queries
    @property
    def n_particles(self) -> int:
        return len(self.masses)

    @property
    def n_springs(self) -> int:
        return len(self.springs)

    def family_index(self, name: str) -> int:
        """Index of a family by name, with an error listing the model's families."""
        try:
            return self.family_names.index(name)
        except ValueError:
            raise ValueError(
                f"unknown spring family {name!r}; this model has {', '.join(self.family_names)}"
            ) from None

    def index(self, row: int, col: int) -> int:
        """Particle index of grid cell ``(row, col)``."""
        if self.cols is None:
            raise ValueError("index(row, col) needs a grid model")
        return (row % self.rows) * self.cols + (col % self.cols)


def _grid_size(size, rows: int, cols: int) -> tuple[float, float]:
    """The spacing ``(along columns, along rows)`` of a ``rows × cols`` grid of ``size`` (w, h)."""
    try:
        w, h = (float(v) for v in size)
    except (TypeError, ValueError):
        raise ValueError(f"size: expected (width, height) in m, got {size!r}") from None
    if not (np.isfinite(w) and np.isfinite(h) and w > 0 and h > 0):
        raise ValueError(f"size: width and height must be finite and > 0 m, got {size!r}")
    if rows < 2 or cols < 2:
        raise ValueError("size: a grid with a size needs at least 2 rows and 2 columns")
    return w / (cols - 1), h / (rows - 1)


def _per_family(name: str, value, families=GRID_FAMILIES) -> dict:

    if isinstance(value, dict):
        unknown = set(value) - set(families)
        if unknown:
            raise ValueError(
                f"{name}: unknown spring families {sorted(map(str, unknown))}; "
                f"expected {', '.join(families)}"
            )
        value = {f: value.get(f, 0.0) for f in families}
    else:
        value = {f: value for f in families}
    return {f: SCHEMA[f"{name}.{f}"].check(v) for f, v in value.items()}
