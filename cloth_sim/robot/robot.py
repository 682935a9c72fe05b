"""A robot from its URDF: its links' collision geometry as collider shapes, and forward kinematics.

The parsing is yourdfpy's (``URDF.load``: links, joints with their origins, axes, limits and
mimics, collisions with their geometry); this module checks what it is given, finds the mesh files
(:mod:`.resources`), reads them once, and makes colliders from each ``<collision>`` (``box``,
``cylinder``, ``sphere``, ``mesh`` with its ``scale``) at its ``origin`` in its link. Joints:
``revolute``, ``continuous``, ``prismatic``, ``fixed``, and ``mimic`` joints (``value = multiplier
· leader + offset``); ``floating`` and ``planar`` joints are refused.

Forward kinematics composes each joint's ``origin`` and its motion (a rotation about, or a
translation along, its axis) down the tree, here rather than through yourdfpy's ``update_cfg`` and
``get_transform``: those walk a trimesh scene graph and took 0.82 ms for the demo arm's 7 links,
where a robot's links move every step (``python -m cloth_sim.bench.robot`` prints both;
``test_robot.py`` holds the two to the same poses).

A :class:`Robot` holds no configuration of its own that a caller could see stale: every query
takes the joint values it is asked about (as yourdfpy's configuration is data one sets and the
poses derived from it).
"""

from __future__ import annotations

import io
import math
import os
from pathlib import Path

import numpy as np

from ..contact import colliders as shapes
from ..physics.mesh import check_indices, read_mesh
from . import resources

#: the joint types a robot may have
JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed")


class Shape:
    """One ``<collision>`` element: its ``link``, its pose in the link (``origin``, 4×4) and a
    collider built at the identity pose by ``make(name, friction)``."""

    def __init__(self, link: str, origin: np.ndarray, kind: str, params: dict):
        self.link, self.origin, self.kind, self.params = link, origin, kind, params

    def make(self, name: str, friction: float):
        p = self.params
        if self.kind == "box":
            return shapes.Box(half_extents=0.5 * p["size"], friction=friction, name=name)
        if self.kind == "cylinder":
            return shapes.Cylinder(
                radius=p["radius"], length=p["length"], friction=friction, name=name
            )
        if self.kind == "sphere":
            return shapes.Sphere(radius=p["radius"], friction=friction, name=name)
        return shapes.Mesh((p["vertices"], p["faces"]), friction=friction, name=name)

    @property
    def triangles(self) -> int:
        return len(self.params["faces"]) if self.kind == "mesh" else 0


class Robot:
    """A robot description: :meth:`from_urdf`."""

    def __init__(self, urdf, name: str, source: str, shapes_: list[Shape]):
        self._urdf = urdf
        #: the URDF's ``<robot name>``
        self.name = name
        #: where it came from: a path, or ``robot_description``
        self.source = source
        #: the collision shapes, link by link in the file's order
        self.shapes = shapes_
        #: movable joints (not fixed, not mimic), in the file's order
        self.joint_names = list(urdf.actuated_joint_names)
        self._mimics = {j.name for j in urdf.robot.joints if j.mimic is not None}
        #: links with at least one collision, in the file's order
        self.link_names = list(dict.fromkeys(s.link for s in shapes_))
        self.all_links = [link.name for link in urdf.robot.links]
        self.root = urdf.base_link
        self._chain = _chain(urdf.robot, self.root)
        self.limits = {
            j.name: (
                (float(j.limit.lower), float(j.limit.upper))
                if j.type != "continuous" and j.limit is not None and j.limit.lower is not None
                else (-math.inf, math.inf)
            )
            for j in urdf.robot.joints
            if j.name in self.joint_names
        }

    # ------------------------------------------------------------------ loading
    @classmethod
    def from_urdf(cls, source, package_paths=()) -> Robot:
        """Load a robot from a URDF file's path or a ``robot_description`` string (XML text).
        ``package://`` URIs are looked up in ``package_paths``, then the ament index
        (``AMENT_PREFIX_PATH``) and ``ROS_PACKAGE_PATH`` (:func:`.resources.package_roots`);
        relative mesh paths from the file's folder. ``ValueError`` naming the element for: XML
        that does not parse, no ``<robot>``, a joint of an unsupported type or naming a missing
        link, a missing mesh file, a mesh with no triangles, a bad size or radius."""
        from lxml import etree  # (yourdfpy's parser)

        if isinstance(source, (str, os.PathLike)) and not str(source).lstrip().startswith("<"):
            path = Path(source)
            if not path.is_file():
                raise ValueError(f"{source}: no such URDF file")
            text, where, base = path.read_bytes(), str(path), path.parent
        elif isinstance(source, str):
            text, where, base = source.encode(), "robot_description", None
        else:
            raise ValueError(
                f"Robot.from_urdf: source must be a URDF file path or its XML text, got "
                f"{type(source).__name__}"
            )
        try:
            root = etree.fromstring(text, etree.XMLParser(remove_blank_text=True))
        except etree.XMLSyntaxError as e:
            raise ValueError(f"{where}: the URDF does not parse: {e}") from None
        if root.tag != "robot":
            raise ValueError(f"{where}: the root element is <{root.tag}>, not <robot>")
        _check_elements(root, where)
        import yourdfpy

        try:
            urdf = yourdfpy.URDF.load(
                io.BytesIO(text),
                build_scene_graph=True,
                load_meshes=False,
                build_collision_scene_graph=False,
                load_collision_meshes=False,
            )
        except Exception as e:  # noqa: BLE001 — the library's failure is the file's: name it
            raise ValueError(
                f"{where}: the URDF cannot be loaded ({type(e).__name__}: {e})"
            ) from e
        roots = resources.package_roots(package_paths)
        shapes_ = _shapes(urdf, where, base, roots)
        return cls(urdf, urdf.robot.name, where, shapes_)

    # ------------------------------------------------------------------ kinematics
    def check_joints(self, values) -> dict:
        """``values`` (a mapping of joint name to position, rad or m) checked: every name a joint
        of the robot (a mimic joint's name is accepted and ignored: it follows its leader), every
        value a finite number; ``ValueError`` naming the first that is not."""
        if not hasattr(values, "items"):
            raise ValueError(
                f"joint positions must be a mapping of joint name to value, got "
                f"{type(values).__name__}"
            )
        out = {}
        for name, value in values.items():
            if name in self._mimics:
                continue
            if name not in self.joint_names:
                raise ValueError(
                    f"robot {self.name!r} has no movable joint {name!r}; its joints: "
                    f"{', '.join(self.joint_names) or 'none'}"
                )
            try:
                v = float(value)
            except (TypeError, ValueError):
                v = math.nan
            if not math.isfinite(v) or isinstance(value, bool):
                raise ValueError(
                    f"joint {name!r}: position must be a finite number, got {value!r}"
                )
            out[name] = v
        return out

    def link_transforms(self, joints: dict) -> dict[str, np.ndarray]:
        """Each link's pose (4×4) in the robot's root frame at the joint positions ``joints``
        (joints not named at 0)."""
        out = {self.root: np.eye(4)}
        for j in self._chain:  # parents before children
            if j.mimic is not None:
                q = j.mimic.multiplier * float(joints.get(j.mimic.joint, 0.0)) + j.mimic.offset
            else:
                q = float(joints.get(j.name, 0.0))
            out[j.child] = out[j.parent] @ j.origin @ _motion(j.type, j.axis, q)
        return out

    @property
    def tree(self) -> list[tuple[str, str]]:
        """``(parent link, child link)`` of every joint, parents before children (the frames a
        ``robot_state_publisher`` broadcasts)."""
        return [(j.parent, j.child) for j in self._chain]

    def link_transforms_yourdfpy(self, joints: dict) -> dict[str, np.ndarray]:
        """The same poses through yourdfpy's ``update_cfg`` and ``get_transform`` (the reference
        :meth:`link_transforms` is tested and timed against)."""
        self._urdf.update_cfg(np.array([float(joints.get(n, 0.0)) for n in self.joint_names]))
        return {link: self._urdf.get_transform(link) for link in self.all_links}

    def __repr__(self):
        return (
            f"Robot({self.name!r}, {len(self.joint_names)} joints, {len(self.link_names)} links "
            f"with collisions, {sum(s.triangles for s in self.shapes)} mesh triangles)"
        )


class _Joint:
    def __init__(self, j):
        self.name, self.type, self.parent, self.child = j.name, j.type, j.parent, j.child
        self.origin = np.eye(4) if j.origin is None else np.asarray(j.origin, dtype=np.float64)
        axis = np.array([1.0, 0.0, 0.0]) if j.axis is None else np.asarray(j.axis, float)
        self.axis = axis / np.linalg.norm(axis)
        self.mimic = j.mimic
        if j.mimic is not None:
            self.mimic.multiplier = 1.0 if j.mimic.multiplier is None else j.mimic.multiplier
            self.mimic.offset = 0.0 if j.mimic.offset is None else j.mimic.offset


def _chain(robot, root: str) -> list[_Joint]:
    """The joints in an order where each parent link is placed before its children (breadth
    first from the root)."""
    children: dict[str, list] = {}
    for j in robot.joints:
        children.setdefault(j.parent, []).append(j)
    order, frontier = [], [root]
    while frontier:
        link = frontier.pop(0)
        for j in children.get(link, []):
            order.append(_Joint(j))
            frontier.append(j.child)
    return order


def _motion(kind: str, axis: np.ndarray, q: float) -> np.ndarray:
    """A joint's motion at position ``q``: a rotation by ``q`` about ``axis`` (Rodrigues) or a
    translation by ``q`` along it."""
    T = np.eye(4)
    if kind == "prismatic":
        T[:3, 3] = q * axis
    elif kind in ("revolute", "continuous"):
        x, y, z = axis
        c, s = math.cos(q), math.sin(q)
        C = 1.0 - c
        T[:3, :3] = [
            [c + x * x * C, x * y * C - z * s, x * z * C + y * s],
            [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
            [z * x * C - y * s, z * y * C + x * s, c + z * z * C],
        ]
    return T


def _check_elements(root, where: str) -> None:
    """What yourdfpy would let through or fail on obscurely, refused by name."""
    links = {e.get("name") for e in root.findall("link")}
    for e in root.findall("link"):
        if not e.get("name"):
            raise ValueError(f"{where}: a <link> without a name")
    joints = {}
    for e in root.findall("joint"):
        name, kind = e.get("name"), e.get("type")
        if not name:
            raise ValueError(f"{where}: a <joint> without a name")
        if kind not in JOINT_TYPES:
            raise ValueError(
                f"{where}: joint {name!r} has type {kind!r}; accepted: {', '.join(JOINT_TYPES)}"
            )
        for end in ("parent", "child"):
            tag = e.find(end)
            link = tag.get("link") if tag is not None else None
            if link not in links:
                raise ValueError(
                    f"{where}: joint {name!r}: its {end} link {link!r} does not exist"
                )
        joints[name] = e
    for name, e in joints.items():
        mimic = e.find("mimic")
        if mimic is not None and mimic.get("joint") not in joints:
            raise ValueError(
                f"{where}: joint {name!r} mimics {mimic.get('joint')!r}, which does not exist"
            )
    if not links:
        raise ValueError(f"{where}: the robot has no <link>")


def _shapes(urdf, where: str, base, roots) -> list[Shape]:
    out = []
    meshes: dict[tuple, tuple] = {}
    for link in urdf.robot.links:
        for k, col in enumerate(link.collisions):
            what = f"{where}: link {link.name!r}, collision {k}"
            origin = np.eye(4) if col.origin is None else np.asarray(col.origin, dtype=np.float64)
            g = col.geometry
            if g.box is not None:
                size = np.asarray(g.box.size, dtype=np.float64)
                if size.shape != (3,) or not np.all(np.isfinite(size) & (size > 0)):
                    raise ValueError(f"{what}: box size must be 3 numbers > 0, got {g.box.size}")
                out.append(Shape(link.name, origin, "box", {"size": size}))
            elif g.cylinder is not None:
                r, h = (
                    _positive(what, "cylinder radius", g.cylinder.radius),
                    _positive(what, "cylinder length", g.cylinder.length),
                )
                out.append(Shape(link.name, origin, "cylinder", {"radius": r, "length": h}))
            elif g.sphere is not None:
                r = _positive(what, "sphere radius", g.sphere.radius)
                out.append(Shape(link.name, origin, "sphere", {"radius": r}))
            elif g.mesh is not None:
                scale = np.ones(3) if g.mesh.scale is None else np.asarray(g.mesh.scale, float)
                scale = np.broadcast_to(scale.reshape(-1), (3,)).astype(np.float64)
                if not np.all(np.isfinite(scale) & (scale > 0)):
                    raise ValueError(f"{what}: mesh scale must be numbers > 0, got {g.mesh.scale}")
                try:
                    path = resources.resolve(g.mesh.filename, base, roots)
                except ValueError as e:
                    raise ValueError(f"{what}: {e}") from None
                key = (str(path), tuple(scale))
                if key not in meshes:
                    try:
                        v, f, name = read_mesh(str(path))
                        check_indices(v, f, name)
                    except ValueError as e:
                        raise ValueError(f"{what}: {e}") from None
                    meshes[key] = (v * scale, f)
                v, f = meshes[key]
                out.append(Shape(link.name, origin, "mesh", {"vertices": v, "faces": f}))
            else:
                raise ValueError(f"{what}: no geometry (box, cylinder, sphere or mesh)")
    return out


def _positive(what: str, field: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{what}: {field} must be a number > 0, got {value!r}")
    return v
