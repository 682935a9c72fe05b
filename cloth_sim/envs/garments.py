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
* :class:`TshirtFoldEnv` — ClothFold's task on the T-shirt, as GarmentLab folds a top: the shirt
  lies flat, turned by a random angle in ±45°; fold the sleeves in (each about the line up from
  its armpit), then the shirt in half (the hem up onto the shoulders, about the line midway).
  Performance, as ClothFold's: ``−(shape + 1.2 · fixation)``, the shape distance
  (:func:`~cloth_sim.envs.metrics.shape_distance`) between the landmarks and those of the shirt
  folded so (pair by pair, the mean difference of their distances: blind to where it lies), and
  the fixation distance, how far the landmarks no fold moves (armpits, shoulders, collar) moved
  (a crumpled or dragged shirt is no fold); normalized from the start (0) to the perfect fold (1).
"""

from __future__ import annotations

from functools import cached_property

import numpy as np

from ..contact import colliders
from ..model import ClothModel
from ..scene import load_scene
from ..simulator import Simulator
from . import metrics
from .cloth_env import FRAME, ClothEnv
from .tasks import ClothFlattenEnv, ClothFoldEnv


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
        cloth = (  # the scene's fabric (the T-shirt's knit), or its per-family springs
            {"material": s.material}
            if s.material is not None
            else {"density": s.mesh["density"], "stiffness": s.stiffness, "damping": s.damping}
        )
        return ClothModel.from_mesh(
            str(s.mesh["file"]), scale=s.mesh["scale"], model=s.model, **cloth
        )

    def _simulator(self) -> Simulator:
        s = self.scene
        return Simulator(
            self.model,
            "vbd",
            dt=FRAME,
            integrator_options=s.vbd_options(),
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
    instruction = "Spread the crumpled T-shirt out flat on the floor."


class TshirtFoldEnv(GarmentEnv, ClothFoldEnv):
    task = "TshirtFold"
    instruction = "Fold the T-shirt: the sleeves in, then the hem up onto the shoulders."
    #: a box wide enough for the sleeves of a shirt turned by 45°
    picker_bounds = ((-0.7, -0.7, 0.004), (0.7, 0.7, 0.48))

    def folds(self) -> list[tuple[tuple[str, str], np.ndarray, np.ndarray]]:
        """The fold, in the order it is made, on the flat layout (:meth:`flat_positions`): for
        each fold the two landmarks that carry it, a point of its line and the line's normal
        towards the side that moves. The sleeves about the lines up from the armpits (along the
        garment's axis, hem to collar), then the hem onto the shoulders about the line midway."""
        x = self.flat_positions()[:, :2]
        m = self.model.meta["landmarks"]
        across = x[m["hem_right"]] - x[m["hem_left"]]
        across /= np.linalg.norm(across)
        up = np.array([-across[1], across[0]])
        mid = (
            x[m["hem_left"]] + x[m["hem_right"]] + x[m["shoulder_left"]] + x[m["shoulder_right"]]
        ) / 4
        return [
            (("sleeve_left_bottom", "sleeve_left_top"), x[m["armpit_left"]], -across),
            (("sleeve_right_bottom", "sleeve_right_top"), x[m["armpit_right"]], across),
            (("hem_left", "hem_right"), mid, -up),
        ]

    def folded_landmarks(self) -> tuple[np.ndarray, np.ndarray]:
        """The landmarks of the shirt folded perfectly, and which of them no fold moves: on the
        flat layout, each fold mirrors the landmarks on its moving side across its line and puts
        them a layer (two thicknesses) up for each layer below them."""
        m = list(self.model.meta["landmarks"].values())
        x = self.flat_positions()[m]
        still = np.ones(len(m), bool)
        for _, point, normal in self.folds():
            side = (x[:, :2] - point) @ normal
            moved = side > 0
            x[moved, :2] -= 2 * np.outer(side[moved], normal)
            x[moved, 2] = x[:, 2].max() + 2 * self.thickness + (x[:, 2].max() - x[moved, 2])
            still &= ~moved
        return x, still

    def _start(self):
        x = self.sim.positions
        self.pickers.reset(self.sim, [*x[:, :2].mean(axis=0), 0.1])
        self.target, still = self.folded_landmarks()
        self.fixed = self.corners[still]
        self.start_positions = x.copy()
        self.performance_start = self._performance()[0]

    def _performance(self):
        x = self.sim.positions
        shape = metrics.shape_distance(x[self.corners], self.target)
        fixation = metrics.mean_distance(x[self.fixed], self.start_positions[self.fixed])
        return -shape - 1.2 * fixation, dict(shape_distance=shape, fixation_distance=fixation)
