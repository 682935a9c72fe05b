"""Contact: the shared geometric primitives (:mod:`.geometry`), rigid colliders
(:mod:`.colliders`), self-collision (:mod:`.self_collision`) and its bounding-volume tree
(:mod:`.collision_tree`).

What users call: the colliders (``from cloth_sim.contact import Plane, Sphere, Mesh``) and the
self-collision stage."""

from .colliders import Box, Capsule, Collider, Cylinder, Mesh, Plane, Sphere
from .self_collision import SelfCollision

__all__ = ["Box", "Capsule", "Collider", "Cylinder", "Mesh", "Plane", "SelfCollision", "Sphere"]
