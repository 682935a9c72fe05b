"""Gymnasium environments: SoftGym's cloth-manipulation benchmark on cloth_sim's physics.

``import cloth_sim.envs`` registers them, or name the module in the id, which Gymnasium imports:
``gymnasium.make("cloth_sim.envs:cloth_sim/ClothFlatten-v0")`` (Gymnasium 1.x has no plugin entry
points):

=================================  =========================================================
``cloth_sim/ClothFlatten-v0``      pickers, horizon 100, action repeat 8 (SoftGym's defaults)
``cloth_sim/ClothFold-v0``         pickers, horizon 100, action repeat 8
``cloth_sim/ClothDrop-v0``         pickers, horizon 30, action repeat 16
``cloth_sim/ClothFlattenPPP-v0``   pick-and-place, horizon 20, action repeat 1
``cloth_sim/ClothFoldPPP-v0``      pick-and-place, horizon 20, action repeat 1
``cloth_sim/TshirtFlatten-v0``     the T-shirt (:mod:`.garments`), pickers, horizon 100, repeat 8
``cloth_sim/TshirtFold-v0``        the T-shirt, pickers, horizon 100, repeat 8
=================================  =========================================================

Every keyword of :class:`~cloth_sim.envs.cloth_env.ClothEnv` can be passed to ``gymnasium.make``.

``gymnasium.make_vec("cloth_sim/ClothFold-v0", num_envs=N)`` makes
:class:`~cloth_sim.envs.vector.ClothFoldVectorEnv` (its vector entry point: every world in one
batch of cloths, ``device="cuda"`` on a GPU); ``vectorization_mode="sync"`` or ``"async"`` makes
Gymnasium's vector envs of single envs instead, as for the other ids.
"""

from __future__ import annotations

import gymnasium

from .cloth_env import ClothEnv
from .garments import GarmentEnv, TshirtFlattenEnv, TshirtFoldEnv
from .tasks import ClothDropEnv, ClothFlattenEnv, ClothFoldEnv
from .vector import ClothFoldVectorEnv

__all__ = [
    "ClothEnv",
    "ClothFlattenEnv",
    "ClothFoldEnv",
    "ClothFoldVectorEnv",
    "ClothDropEnv",
    "GarmentEnv",
    "TshirtFlattenEnv",
    "TshirtFoldEnv",
    "ENV_IDS",
    "register",
]

_ENVS = {
    "cloth_sim/ClothFlatten-v0": ("ClothFlattenEnv", {}),
    "cloth_sim/ClothFold-v0": ("ClothFoldEnv", {}),
    "cloth_sim/ClothDrop-v0": ("ClothDropEnv", {}),
    "cloth_sim/ClothFlattenPPP-v0": (
        "ClothFlattenEnv",
        dict(action_mode="pickerpickplace", horizon=20),
    ),
    "cloth_sim/ClothFoldPPP-v0": ("ClothFoldEnv", dict(action_mode="pickerpickplace", horizon=20)),
    "cloth_sim/TshirtFlatten-v0": ("garments:TshirtFlattenEnv", {}),
    "cloth_sim/TshirtFold-v0": ("garments:TshirtFoldEnv", {}),
}
ENV_IDS = tuple(_ENVS)
#: the ids with a vector env of their own (``gymnasium.make_vec``'s default for them)
_VECTOR = {"cloth_sim/ClothFold-v0": "cloth_sim.envs.vector:ClothFoldVectorEnv"}


def register() -> None:
    """Register the environments with Gymnasium (done on import; again is a no-op)."""
    for env_id, (cls, kwargs) in _ENVS.items():
        if env_id not in gymnasium.registry:
            module, _, name = cls.rpartition(":")
            entry = f"cloth_sim.envs.{module or 'tasks'}:{name}"
            gymnasium.register(
                id=env_id,
                entry_point=entry,
                vector_entry_point=_VECTOR.get(env_id),
                kwargs=kwargs,
            )


register()
