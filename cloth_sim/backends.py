"""Where a cloth is stepped: the device is its own axis beside the method.

``Simulator(model, integrator="vbd", dt=1/60, device="cuda")`` keeps the method's name and asks
this registry for the device's implementation: ``cpu`` is :class:`cloth_sim.Simulator` itself
(every method), ``cuda`` is :mod:`cloth_sim.cuda` (numba-cuda, an optional dependency:
``requirements-gpu.txt``, ``make gpu``), which runs the methods in :data:`METHODS`. A device
that is named but cannot run here is refused by :func:`check_device` with what is missing.
"""

from __future__ import annotations

import copy
import importlib
import importlib.util

import numpy as np

from .kinds import DEVICES, LINEAR
from .model import ClothModel

__all__ = ["DEVICES", "check_device", "check_method", "implementation", "problem", "refusal"]

#: the methods each device runs (``None``: every registered method)
METHODS: dict[str, tuple[str, ...] | None] = {
    "cpu": None,
    "cuda": ("symplectic_euler", "vbd"),
}

#: the methods under which each device sweeps a collider moved over a step (a robot's links, a
#: pose set without teleport) through its contact stage (``None``: every method)
SWEEPS: dict[str, tuple[str, ...] | None] = {
    "cpu": None,
    "cuda": ("symplectic_euler",),
}

#: each device's implementation: ``(module, single-world class, batch class)``
_IMPLEMENTATIONS = {
    "cuda": ("cloth_sim.cuda.simulator", "CudaSimulator", "CudaBatchSimulator"),
}


def problem(device: str) -> str | None:
    """Why ``device`` cannot run here, in words a user can act on (``None`` when it can). Unknown
    names are a problem too."""
    if device not in DEVICES:
        return f"device must be one of {', '.join(DEVICES)}, got {device!r}"
    if device == "cpu":
        return None
    if importlib.util.find_spec("numba_cuda") is None:
        return (
            "device 'cuda' needs numba-cuda, which is not installed: `make gpu` installs "
            "requirements-gpu.txt into the venv"
        )
    # the optional dependency is imported only when a user names its device
    return importlib.import_module("cloth_sim.cuda").problem()


def check_device(device) -> str:
    """``device`` if it can run here, else ``ValueError`` naming what is missing."""
    if not isinstance(device, str):
        raise ValueError(f"device must be one of {', '.join(DEVICES)}, got {device!r}")
    why = problem(device)
    if why is not None:
        raise ValueError(why)
    return device


def sweeps_colliders(device: str, method: str) -> bool:
    """Whether ``device`` sweeps a moving collider over a step of ``method`` (:data:`SWEEPS`):
    where it does not, a robot is refused and a collider's pose is placed by teleport."""
    methods = SWEEPS[device]
    return methods is None or method in methods


def check_method(method: str, device: str) -> None:
    """``ValueError`` where ``device`` has no implementation of ``method``."""
    methods = METHODS[device]
    if methods is not None and method not in methods:
        raise ValueError(
            f"integrator {method!r} has no {device} backend; on {device}: {', '.join(methods)} "
            "(device='cpu' runs every method)"
        )


def refusal(device: str, integrator: str, model: ClothModel, **features) -> tuple[str, str] | None:
    """Why ``device`` cannot step ``model`` with ``integrator`` and ``features`` (keyword: a
    feature's name and whether it is asked for: ``strain_limit_method`` (a strain limit by a
    method other than Provot's passes), ``self_collision``, ``grippers``, ``robot``), as
    ``(reason, the argument it names)``, or ``None``. Nothing is refused on the cpu; what
    :mod:`cloth_sim.cuda` does not run yet is refused on cuda."""
    if device == "cpu":
        return None
    methods = METHODS[device]
    if integrator not in methods:
        return (
            f"integrator {integrator!r} has no {device} backend; on {device}: "
            f"{', '.join(methods)} (device='cpu' runs every method)",
            "integrator",
        )
    for name, asked in features.items():
        if asked:
            hint = {
                "strain_limit_method": " (the projection is not; Provot's passes, "
                "strain_limit_method provot, are)",
                "robot": f" under {integrator} (a robot's links sweep over each step; under "
                "symplectic_euler they do)",
                "grippers": f" on a robot's links under {integrator} (under symplectic_euler "
                "they are)",
            }.get(name, "")
            return (
                f"{name}: not on the {device} device yet{hint}; it runs springs, bending, "
                "gravity, wind, drag, pins, grippers, colliders (a mesh from its distance grid), "
                "Provot's strain limit and robots under symplectic_euler, and device='cpu' has "
                "the rest",
                name,
            )
    if len(model.kind) and int(max(model.kind)) != LINEAR:
        return (
            f"model {model.model!r}: Choi & Ko's tension-only and buckling pairs are not on the "
            f"{device} device yet (Hooke springs and a material's bending are); device='cpu' runs "
            "them",
            "model",
        )
    return None


def implementation(device: str, batch: bool = False):
    """The class that steps a cloth (``batch``: many worlds) on ``device`` (checked first)."""
    check_device(device)
    module, single, many = _IMPLEMENTATIONS[device]
    return getattr(importlib.import_module(module), many if batch else single)


def world_ids(worlds, count: int):
    """``worlds`` (indices, or ``None`` for all ``count``) as an int64 array, each checked."""
    ids = np.arange(count) if worlds is None else np.asarray(worlds, np.int64).ravel()
    if ids.size and (ids.min() < 0 or ids.max() >= count):
        raise ValueError(f"worlds: indices must lie in [0, {count - 1}], got {ids.tolist()}")
    return ids


def world_pairs(worlds, indices, count: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(worlds, indices)`` as rows, one vertex ``indices[r]`` of world ``worlds[r]`` a row, the
    worlds checked as :func:`world_ids` and the vertices against ``n``."""
    w = world_ids(np.asarray(worlds, np.int64).ravel(), count)
    i = np.asarray(indices, np.int64).ravel()
    if len(w) != len(i):
        raise ValueError(
            f"worlds and indices: one vertex a row, got {len(w)} worlds and {len(i)} indices"
        )
    if i.size and (i.min() < 0 or i.max() >= n):
        raise ValueError(f"indices must lie in [0, {n - 1}]")
    return w, i


def models_of(models, worlds: int | None) -> list[ClothModel]:
    """One model ``worlds`` times, or the list given (``worlds`` then its length, or None)."""
    if isinstance(models, ClothModel):
        count = 1 if worlds is None else worlds
        if isinstance(count, bool) or int(count) != count or not 1 <= count <= 1_000_000:
            raise ValueError(f"worlds must be an integer in [1, 1000000], got {worlds!r}")
        return [models] * int(count)
    models = list(models)
    if not models or not all(isinstance(m, ClothModel) for m in models):
        raise ValueError("models must be a ClothModel or a non-empty list of them")
    if worlds is not None and worlds != len(models):
        raise ValueError(f"worlds={worlds} but {len(models)} models were given")
    return models


def world_vectors(name: str, value, count: int) -> np.ndarray:
    """``value``, a 3-vector or one a world, as ``(count, 3)`` (a read-only broadcast of one):
    a batch's ``set(worlds, gravity=..., wind=...)`` on every device, or ``ValueError`` naming
    ``name``."""
    a = np.asarray(value, np.float64)
    if a.shape not in ((3,), (count, 3)) or not np.all(np.isfinite(a)):
        raise ValueError(
            f"{name} must be a finite 3-vector or one a world ({count}, 3), got {value!r}"
        )
    return np.broadcast_to(a, (count, 3))


def placed_collider(shapes: list, index, pose):
    """A copy of collider ``index`` of ``shapes`` placed at ``pose``, ``(position,
    orientation)``, checked as the shape checks a pose: what a batch's ``set(worlds,
    colliders={index: pose})`` puts in those worlds on every device, or ``ValueError`` naming
    the index or the field (nothing changed)."""
    if not (isinstance(index, (int, np.integer)) and 0 <= index < len(shapes)):
        raise ValueError(
            f"colliders: index {index!r} must lie in [0, {len(shapes) - 1}]"
            if shapes
            else f"colliders: index {index!r}, but these worlds have no collider"
        )
    try:
        position, orientation = pose
    except (TypeError, ValueError):
        raise ValueError(
            f"colliders[{index}] must be (position, orientation), got {pose!r}"
        ) from None
    shape = copy.copy(shapes[index])
    try:
        shape.set_pose(position, orientation)
    except ValueError as e:
        raise ValueError(f"colliders[{index}]: {e}") from None
    return shape
