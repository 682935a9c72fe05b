"""The entities the ROS simulation standard sees in cloth_sim: their names, categories, information
and bounds, and the filters of ``get_entities``.

* ``cloth`` — the cloth, ``CATEGORY_OBJECT``;
* ``collider/<name>`` — each collider, the scene's and those spawned: ``CATEGORY_STATIC_OBJECT``
  (it moves only when a pose is set or streamed), unless ``set_entity_info`` gives it another
  category — ``CATEGORY_DYNAMIC_OBJECT`` for a kinematic obstacle that moves at a twist it is given
  (the standard refuses a twist for a static object);
* ``gripper/<name>`` — each gripper holding the cloth, ``CATEGORY_ROBOT``;
* ``robot/<name>`` — each robot (a URDF's links as colliders, :mod:`cloth_sim.robot`), its pose its
  root link's, and ``robot/<name>/<link>`` each of its links with a collision, its pose the
  link's: ``CATEGORY_ROBOT`` (their colliders are not listed apart: the joints move them).

A full name is what ``get_entities`` lists and ``spawn_entity`` answers; a client may also use the
name it gave (``ball`` for ``collider/ball``, as Gazebo's and Isaac Sim's clients do) wherever that
names one entity. ``set_entity_info`` sets a collider's category and any entity's description and
tags (``get_entities`` filters by them); a reset or a new scene forgets what it set.

Bounds (``get_entity_bounds``, and the overlap filter): the axis-aligned box of the entity
(``TYPE_BOX``, as the standard asks), empty for a plane (unbounded). The filter takes a sphere
(exact for every collider shape, by its signed distance; the cloth by its particles) or a box (the
entities' boxes overlapping it; a plane by the side its corners are on).
"""

from __future__ import annotations

import re

import numpy as np
from simulation_interfaces.msg import Bounds, EntityCategory, Result, TagsFilter

from ..contact.colliders import Box, Capsule, Cylinder, Mesh, Plane, Sphere

CLOTH = "cloth"
#: the categories each kind of entity reports unless set otherwise
DEFAULT_CATEGORY = {
    "cloth": EntityCategory.CATEGORY_OBJECT,
    "collider": EntityCategory.CATEGORY_STATIC_OBJECT,
    "gripper": EntityCategory.CATEGORY_ROBOT,
    "robot": EntityCategory.CATEGORY_ROBOT,
}
CATEGORY_NAMES = {
    getattr(EntityCategory, n): n for n in dir(EntityCategory) if n.startswith("CATEGORY_")
}


class Entities:
    """The entity table over the session's simulator (``session.sim``, read at each call)."""

    def __init__(self, session, manipulation):
        self.session, self.manipulation = session, manipulation
        #: full name -> (category, description or None, tags) set by set_entity_info
        self._set: dict[str, tuple[int, str | None, tuple[str, ...]]] = {}

    # ------------------------------------------------------------------ names
    def names(self) -> list[str]:
        """Every entity's full name: the cloth, the colliders in order, the grippers."""
        sim = self.session.sim
        robots = []
        for name, robot in sim.robots.items():
            robots += [f"robot/{name}", *(f"robot/{name}/{link}" for link in robot.link_names)]
        names = [
            CLOTH,
            # (a robot's link colliders, named robot/link, are its entities)
            *(f"collider/{c.name}" for c in sim.colliders if "/" not in c.name),
            *robots,
            *(f"gripper/{g}" for g in sim.grippers),
        ]
        for gone in set(self._set) - set(names):  # what set_entity_info set goes with its entity
            del self._set[gone]
        return names

    def taken(self) -> set[str]:
        """Every entity's full name and own name (``collider/ball`` and ``ball``): what a spawned
        entity may not be called."""
        names = self.names()
        return set(names) | {n.partition("/")[2] for n in names}

    def resolve(self, name: str) -> str | None:
        """The full name ``name`` stands for: itself, or the one entity whose own name it is
        (``ball`` for ``collider/ball``); ``None`` when it names none, or more than one."""
        names = self.names()
        if name in names:
            return name
        matches = [n for n in names if n.partition("/")[2] == name]
        return matches[0] if len(matches) == 1 else None

    def unknown(self, name: str) -> Result:
        names = self.names()
        same = [n for n in names if n.partition("/")[2] == name]
        if len(same) > 1:
            return Result(
                result=Result.RESULT_NOT_FOUND,
                error_message=(
                    f"entity {name!r} is ambiguous: it names {', '.join(same)}; give the full name"
                ),
            )
        return Result(
            result=Result.RESULT_NOT_FOUND,
            error_message=(
                f"no entity {name!r}; entities: {', '.join(names)} (a collider or gripper also by "
                "its "
                f"own name)"
            ),
        )

    # ------------------------------------------------------------------ information
    def info(self, name: str) -> tuple[int, str, tuple[str, ...]]:
        """``(category, description, tags)`` of the entity with full name ``name``."""
        kind = name.partition("/")[0]
        category, description, tags = self._set.get(name, (DEFAULT_CATEGORY[kind], None, ()))
        return category, description if description is not None else self._describe(name), tags

    def _describe(self, name: str) -> str:
        sim = self.session.sim
        kind, _, key = name.partition("/")
        if kind == "cloth":
            return (
                f"the cloth: {sim.model.n_particles} particles, {len(sim.model.triangles)} "
                f"triangles"
            )
        if kind == "gripper":
            return f"a gripper holding {len(sim.grippers[key])} particles"
        if kind == "robot":
            robot_name, _, link = key.partition("/")
            robot = sim.robots[robot_name]
            if link:
                return f"link {link} of robot {robot_name} (moved by its joints)"
            return (
                f"a robot from the URDF {robot.name!r}: {len(robot.joint_names)} joints, "
                f"{len(robot.link_names)} links with collisions"
            )
        c = self.collider(key)
        return f"a {type(c).__name__.lower()} collider (kinematic: moved by its pose or a twist)"

    def is_static(self, name: str) -> bool:
        return self.info(name)[0] == EntityCategory.CATEGORY_STATIC_OBJECT

    def set_info(self, name: str, category: int, description: str, tags) -> Result:
        """What ``set_entity_info`` asks (``name`` resolved): a collider may take any category; the
        cloth and a gripper keep theirs. An empty description keeps the generated one."""
        kind = name.partition("/")[0]
        if category not in CATEGORY_NAMES:
            return Result(
                result=Result.RESULT_OPERATION_FAILED,
                error_message=(
                    f"info.category.category = {category}: expected one of "
                    f"{', '.join(f'{v} ({n})' for v, n in sorted(CATEGORY_NAMES.items()))}"
                ),
            )
        if kind != "collider" and category != DEFAULT_CATEGORY[kind]:
            return Result(
                result=Result.RESULT_OPERATION_FAILED,
                error_message=(
                    f"info.category.category = {category}: {name} is always "
                    f"{CATEGORY_NAMES[DEFAULT_CATEGORY[kind]]} (a collider's category can be set)"
                ),
            )
        if kind == "collider" and category == EntityCategory.CATEGORY_STATIC_OBJECT:
            self.manipulation.set_twist(
                "collider", name.partition("/")[2], 0, 0
            )  # static: it stops
        self._set[name] = (category, description or None, tuple(tags))
        return Result(result=Result.RESULT_OK)

    def forget(self, keep=()) -> None:
        """Forget what set_entity_info set (a reset, a new scene), but for the entities ``keep``
        names."""
        self._set = {n: v for n, v in self._set.items() if n in keep}

    # ------------------------------------------------------------------ filters
    def matching(self, filters) -> tuple[list[str] | None, Result]:
        """The full names the standard's ``EntityFilters`` select, or ``None`` and the reason."""
        try:
            pattern = re.compile(filters.filter)
        except re.error as e:
            return None, Result(
                result=Result.RESULT_OPERATION_FAILED,
                error_message=(
                    f"filters.filter = {filters.filter!r} is not a regular expression ({e})"
                ),
            )
        b = filters.bounds
        if b.type not in (Bounds.TYPE_EMPTY, Bounds.TYPE_BOX, Bounds.TYPE_SPHERE):
            return None, Result(
                result=Result.RESULT_FEATURE_UNSUPPORTED,
                error_message=(
                    f"filters.bounds.type = {b.type}: cloth_sim filters by TYPE_SPHERE and "
                    "TYPE_BOX "
                    f"bounds (TYPE_CONVEX_HULL is not supported)"
                ),
            )
        if b.type != Bounds.TYPE_EMPTY:
            if len(b.points) != 2:
                return None, Result(
                    result=Result.RESULT_OPERATION_FAILED,
                    error_message=(
                        f"filters.bounds.points: {len(b.points)} points; a sphere or box has 2"
                    ),
                )
            pts = np.array([[p.x, p.y, p.z] for p in b.points])
            if not np.all(np.isfinite(pts)) or (b.type == Bounds.TYPE_SPHERE and pts[1, 0] < 0):
                return None, Result(
                    result=Result.RESULT_OPERATION_FAILED,
                    error_message=(
                        f"filters.bounds.points = {pts.tolist()}: expected finite points (a "
                        "sphere's "
                        f"radius, the second point's x, at least 0)"
                    ),
                )
        categories = {c.category for c in filters.categories}
        wanted = set(filters.tags.tags)
        every = filters.tags.filter_mode == TagsFilter.FILTER_MODE_ALL
        out = []
        for name in self.names():
            category, _, tags = self.info(name)
            if not pattern.search(name) or (categories and category not in categories):
                continue
            if wanted and not (wanted <= set(tags) if every else wanted & set(tags)):
                continue
            if b.type != Bounds.TYPE_EMPTY and not self._overlaps(name, b.type, pts):
                continue
            out.append(name)
        return out, Result(result=Result.RESULT_OK)

    def _overlaps(self, name: str, kind: int, pts: np.ndarray) -> bool:
        sim = self.session.sim
        entity, _, key = name.partition("/")
        if kind == Bounds.TYPE_SPHERE:
            centre, radius = pts[0], pts[1, 0]
            if entity == "collider":
                return float(self.collider(key).signed_distance(centre[None])[0]) <= radius
            if entity == "robot":
                return any(
                    float(c.signed_distance(centre[None])[0]) <= radius
                    for c in self.robot_colliders(key)
                )
            x = sim.positions if entity == "cloth" else sim.positions[sim.grippers[key]]
            return bool((np.linalg.norm(x - centre, axis=1) <= radius).any())
        lo, hi = np.minimum(pts[0], pts[1]), np.maximum(pts[0], pts[1])
        if entity == "collider" and isinstance(self.collider(key), Plane):
            c = self.collider(key)
            corners = np.array(
                [[a[0], b[1], d[2]] for a in (lo, hi) for b in (lo, hi) for d in (lo, hi)]
            )
            side = corners @ c.normal - c.offset
            return bool(side.min() <= 0.0)  # some of the box is on the plane or behind it
        box = self.box(name)
        return bool(np.all(box[0] <= hi) and np.all(lo <= box[1]))

    # ------------------------------------------------------------------ geometry
    def collider(self, name: str):
        return next(c for c in self.session.sim.colliders if c.name == name)

    def robot_colliders(self, key: str) -> list:
        """The colliders of robot ``key`` (``name``), or of one of its links (``name/link``)."""
        robot, _, link = key.partition("/")
        prefix = f"{robot}/{link}" if link else f"{robot}/"
        return [
            c
            for c in self.session.sim.colliders
            if c.name == prefix or c.name.startswith(prefix if not link else prefix + "/")
        ]

    def box(self, name: str) -> tuple[np.ndarray, np.ndarray] | None:
        """``(min, max)`` corners of the entity's axis-aligned bounding box; ``None`` for a
        plane."""
        sim = self.session.sim
        entity, _, key = name.partition("/")
        if entity == "cloth":
            pts = sim.positions
        elif entity == "gripper":
            pts = sim.positions[sim.grippers[key]]
        elif entity == "robot":
            pts = np.concatenate([collider_extent(c) for c in self.robot_colliders(key)])
        else:
            pts = collider_extent(self.collider(key))
            if pts is None:
                return None
        return pts.min(axis=0), pts.max(axis=0)


def collider_extent(c) -> np.ndarray | None:
    """Points whose box bounds the collider; ``None`` for a plane (unbounded)."""
    if isinstance(c, Sphere):
        return np.stack([c.center - c.radius, c.center + c.radius])
    if isinstance(c, Box):
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        return (corners * c.half_extents) @ c.rotation.T + c.center
    if isinstance(c, Capsule):
        ends = np.stack([c.a, c.b])
        return np.concatenate([ends - c.radius, ends + c.radius])
    if isinstance(c, Cylinder):
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        half = np.array([c.radius, c.radius, 0.5 * c.length])
        return (corners * half) @ c.rotation.T + c.center
    if isinstance(c, Mesh):
        return c.vertices
    return None
