"""Contact: the shared geometric primitives (:mod:`.geometry`), rigid colliders
(:mod:`.colliders`), self-collision (:mod:`.self_collision`) and its bounding-volume tree
(:mod:`.collision_tree`); the colliders' and self-collision's kernels are
:mod:`.collider_kernels` and :mod:`.self_collision_kernels`.

What users call, imported when first used: the colliders (``from cloth_sim.contact import Plane,
Sphere, Mesh``) and the self-collision stage."""

from ..lazy import exports

_NAMES = {
    **{
        name: ".colliders"
        for name in ("Box", "Capsule", "Collider", "Cylinder", "Mesh", "Plane", "Sphere")
    },
    "SelfCollision": ".self_collision",
}
__all__ = sorted(_NAMES)
__getattr__, __dir__ = exports(__name__, _NAMES)
