"""Contact: the shared geometric primitives (:mod:`.geometry`), rigid colliders
(:mod:`.colliders`),
self-collision (:mod:`.self_collision`) and its bounding-volume tree (:mod:`.collision_tree`)."""
