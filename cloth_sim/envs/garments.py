"""Garment tasks: SoftGym's cloth tasks on a garment's mesh instead of its square cloth.

:class:`GarmentEnv` puts a shipped garment (``config/meshes/<garment>.obj``, its material from the
scene of the same name) in :class:`~cloth_sim.envs.cloth_env.ClothEnv`'s place of the grid: the
simulation is the garment scene's, ``vbd`` at a frame a step with self-contact inside the solve,
over a floor; ``"key_point"`` observes the garment's named vertices (its landmarks,
:func:`cloth_sim.physics.mesh.read_landmarks`) in their file's order; laid flat, the garment's
panels lie on the floor a thickness apart (the back below, the seams between, the front on top).

* :class:`TshirtFlattenEnv` — ClothFlatten's task on the T-shirt: dropped crumpled from a random
  particle, spread it out; performance the covered area (a particle covering half an edge), the
  normalized one from the start to the shirt laid flat.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np

from ..contact import colliders
from ..model import ClothModel
from ..scene import load_scene
from ..simulator import Simulator
from .cloth_env import FRAME, ClothEnv
from .tasks import ClothFlattenEnv


class GarmentEnv(ClothEnv):
    """A garment in the grid's place (see the module docstring); ``cloth_size`` and ``spacing``
    do not apply. ``self_collision`` is on unless turned off."""

    #: the shipped garment: ``config/meshes/<garment>.obj`` and the scene of that name
    garment = "tshirt"
    #: its mesh's edge length (m): ``tools/make_garments.py``'s ``EDGE``
    edge = 0.025
    substeps = 1  # vbd: one step a frame

    def __init__(self, *args, self_collision: bool = True, **kwargs):
        super().__init__(*args, self_collision=self_collision, **kwargs)

    @cached_property
    def scene(self):
        return load_scene(self.garment)

    def _model(self) -> ClothModel:
        s = self.scene
        return ClothModel.from_mesh(
            str(s.mesh["file"]),
            density=s.mesh["density"],
            stiffness=s.stiffness,
            damping=s.damping,
            scale=s.mesh["scale"],
            model=s.model,
        )

    def _simulator(self) -> Simulator:
        s = self.scene
        return Simulator(
            self.model,
            "vbd",
            dt=FRAME,
            integrator_options={"iterations": s.vbd_iterations},
            strain_limit=s.strain_limit,
            colliders=[colliders.Plane(normal=(0, 0, 1), offset=0.0, friction=0.5, name="floor")],
            thickness=self.thickness,
            self_collision=self.self_collision,
        )

    def _key_points(self) -> np.ndarray:
        return np.array(list(self.model.meta["landmarks"].values()), dtype=np.int64)

    @property
    def key_point_names(self) -> tuple[str, ...]:
        """The landmarks ``"key_point"`` observes, in order."""
        return tuple(self.model.meta["landmarks"])

    def _cache_key(self) -> dict:
        key = super()._cache_key()
        key.update(garment=self.garment, rows=None, cols=None, spacing=None, edge=self.edge)
        return key

    def flat_positions(self) -> np.ndarray:
        """The garment laid flat on the floor, centred on the origin: its outline as cut, the back
        panel a thickness up, the seams two, the front three."""
        x = self.model.positions.copy()
        x[:, :2] -= x[:, :2].mean(axis=0)
        x[:, 2] = self.thickness * (2.0 + np.sign(np.round(x[:, 2], 9)))
        return x

    @property
    def radius(self) -> float:
        return self.edge / 2


class TshirtFlattenEnv(GarmentEnv, ClothFlattenEnv):
    task = "TshirtFlatten"
