"""The node's settings as plain values — what a scene implies, which combinations are refused, and
the simulator they build — with no ROS, so that the node's parameter gate
(:mod:`cloth_sim.ros.gate`) and the sweeps (:mod:`cloth_sim.sweep`) give a value the same meaning
and refuse it for the same reason.

A *configuration* is a dict holding a value for every name of :data:`~cloth_sim.parameters.SCHEMA`
(:func:`defaults` gives a scene's). :func:`configure` checks one made from a scene and overrides
exactly as the node checks a parameter change and builds its simulator.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from . import backends, integrators
from .constraints.strain_limit import DEFAULT_STRAIN_LIMIT_PASSES
from .contact.self_collision import check_thickness
from .integrators.base import Stability
from .materials import get
from .parameters import REBUILD, SCHEMA, ParameterError
from .physics import stability as stab
from .scene import Scene, load_scene
from .sensors.camera import camera_from_settings
from .simulator import Simulator
from .simulator_options import options as simulator_options

#: the rebuild parameters that shape the model (``scene`` is the other one)
MODEL_KEYS = tuple(name for name in REBUILD if name != "scene")
#: the parameters that shape a grid only, and a mesh only: a scene of the other kind refuses a
#: change
GRID_ONLY = (
    "rows",
    "cols",
    "spacing",
    "particle_mass",
    "stiffness.shear",
    "damping.shear",
    "size",
)
MESH_ONLY = ("density",)
#: what those parameters hold while the scene does not use them (start-up on a scene of the other
#: kind; they keep their values across scene changes)
UNUSED_VALUES = {
    "rows": 32,
    "cols": 32,
    "spacing": 1.0 / 31,
    "particle_mass": 0.01,
    "stiffness.shear": 0.0,
    "damping.shear": 0.0,
    "density": 0.1,
    "size": [0.0, 0.0],
}
#: the camera's parameters, without their ``camera.`` prefix
CAMERA_SETTINGS = (
    "enable",
    "width",
    "height",
    "fov",
    "position",
    "look_at",
    "rate",
    "near",
    "far",
    "noise",
)


def defaults(scene: Scene) -> dict:
    """Every parameter's value on ``scene`` before anything is set."""
    values = {
        "scene": scene.name,
        "allow_unstable": False,
        "publish_rate": 60.0,
        "frame_id": "cloth",
        "world_frame_id": "world",
        "publish_clock": False,
        "real_time_factor": 1.0,
        "strain_limit_passes": DEFAULT_STRAIN_LIMIT_PASSES,
        "vbd.fit_tick": False,
        "robot.enable": False,
        "robot.description_topic": "/robot_description",
        "robot.joint_states_topic": "/joint_states",
        "robot.source": "joint_states",
        "robot.base_frame": "",
        "device": "cpu",
    }
    values.update(UNUSED_VALUES)
    values.update(scene.parameter_values())
    return values


def fabric(cfg: dict, scene: Scene):
    """The fabric ``cfg`` maps onto ``scene``'s cloth: the ``material`` parameter's library
    fabric, else the scene's own, else None (per-family springs)."""
    if cfg["material"]:
        return get(cfg["material"])
    return scene.material


#: what a grid's mass per area sets (a scene's ``density:``): its particles' equal shares
DENSITY_SETS = ("particle_mass",)
#: the parameters a material sets itself (refused while one is in use)
MATERIAL_SETS = ("particle_mass", "density")


def _material_set(scene: Scene) -> tuple[str, ...]:
    """What a material sets on ``scene``'s cloth: the masses and every family's values."""
    return (
        *MATERIAL_SETS,
        *(f"{kind}.{f}" for kind in ("stiffness", "damping") for f in scene.families),
    )


def inapplicable_changes(scene: Scene, cand: dict, current: dict) -> list[str]:
    """The parameters ``scene``'s cloth does not have (a grid's size on a mesh, a mesh's density
    on a grid; the masses and springs a material sets) that ``cand`` changes from ``current``."""
    names = GRID_ONLY if scene.mesh is not None else MESH_ONLY
    if scene.mesh is None and scene.grid_density is not None:
        names = DENSITY_SETS
    if fabric(cand, scene) is not None and fabric(current, scene) is not None:
        names = (*names, *_material_set(scene))
    return [n for n in dict.fromkeys(names) if cand[n] != current[n]]


def not_applicable(scene: Scene, cand: dict, current: dict) -> str | None:
    """The reason to refuse a change of a parameter ``scene``'s cloth does not have (a grid's size
    on a mesh, a mesh's density on a grid; what a material sets), ``None`` when there is none."""
    changed = inapplicable_changes(scene, cand, current)
    if not changed:
        return None
    if fabric(cand, scene) is not None:
        sets = _material_set(scene)
        set_by = [n for n in changed if n in sets]
        if set_by:
            which = cand["material"] or f"scene {scene.name}'s"
            return (
                f"{', '.join(set_by)}: set by the cloth's material ({which}) from the fabric "
                f"in SI units; set material to '' on a scene without one to use per-family "
                f"values"
            )
    if scene.mesh is None and scene.grid_density is not None:
        return (
            f"{', '.join(changed)}: set by scene {scene.name}'s density (kg/m²): its rows·cols "
            f"particles share the cloth's mass equally at any resolution; set density instead"
        )
    if scene.mesh is not None:
        return (
            f"{', '.join(changed)}: not used by scene {scene.name}, a triangle mesh "
            f"({scene.mesh['file'].name}): its particles are the mesh's vertices, its masses come "
            "from density (kg/m²) and its springs are structural (edges) and bend (across "
            "edges), "
            f"no shear"
        )
    return (
        f"{', '.join(changed)}: not used by scene {scene.name}, a {scene.rows}×{scene.cols} grid "
        f"(its masses come from particle_mass); density applies to mesh scenes and to grid "
        f"scenes that give their mass per area"
    )


def camera_settings(cfg: dict) -> dict:
    return {k: cfg[f"camera.{k}"] for k in CAMERA_SETTINGS}


def camera_reason(cfg: dict) -> str | None:
    """The reason ``cfg``'s camera cannot be built (naming the parameter), ``None`` when it can or
    is off."""

    if not cfg["camera.enable"]:
        return None
    try:
        camera_from_settings(camera_settings(cfg))
    except ValueError as e:
        return str(e)
    return None


def material(model, cfg: dict) -> tuple[np.ndarray, np.ndarray]:
    """Per-spring stiffness and damping of ``model`` from the family parameters in ``cfg``; a
    model built from a fabric keeps its own (the fabric's mapping)."""
    if model.meta.get("material") is not None:
        return model.stiffness, model.damping
    k = np.array([cfg[f"stiffness.{f}"] for f in model.family_names])[model.family]
    c = np.array([cfg[f"damping.{f}"] for f in model.family_names])[model.family]
    return k, c


def build_model(cfg: dict, scene: Scene):
    """``scene``'s model with ``cfg``'s size or density, spring model and material."""
    size = (
        {"density": cfg["density"]}
        if scene.mesh is not None
        else {k: cfg[k] for k in ("rows", "cols", "spacing", "particle_mass")}
    )
    if scene.mesh is None:
        w, h = cfg["size"]
        if (w > 0) != (h > 0):
            raise ValueError(f"size: [width, height] must be both > 0 or both 0, got {[w, h]}")
        size["size"] = (w, h) if w > 0 else None
        if scene.grid_density is not None:
            size["density"] = cfg["density"]
    return scene.build_model(
        **size,
        material=fabric(cfg, scene),
        model=cfg["model"],
        stiffness={f: cfg[f"stiffness.{f}"] for f in scene.families},
        damping={f: cfg[f"damping.{f}"] for f in scene.families},
    )


def build_simulator(cfg: dict, model, scene: Scene) -> Simulator:
    """A simulator of ``model`` (built for ``scene``) with ``cfg``'s live values, the scene's
    colliders and grippers."""
    sim = Simulator(
        model,
        **simulator_options(cfg),
        colliders=scene.make_colliders(),
    )
    if scene.robot is not None:
        scene.add_robot(sim)
    scene.apply_grippers(sim)
    sim.motion = scene.motion
    k, c = material(model, cfg)
    if not (np.array_equal(model.stiffness, k) and np.array_equal(model.damping, c)):
        for f in model.family_names:  # a kept model built with other values: set them
            sim.set_stiffness(f, cfg[f"stiffness.{f}"])
            sim.set_damping(f, cfg[f"damping.{f}"])
    return sim


def check_stability(cfg: dict, model) -> tuple[str | None, float]:
    """``(reason, stable_dt)``: the limit of ``cfg``'s method on ``model`` with ``cfg``'s material
    (computed once per material and method, :mod:`cloth_sim.physics.stability`), and the reason to
    refuse ``cfg["dt"]`` above it (``None`` when fine or ``allow_unstable``)."""
    k, c = material(model, cfg)
    analysis = stab.analysis_for(model, k, c, cfg["drag"])
    integ = integrators.get(cfg["integrator"])(model)
    limit = integ.stable_dt(analysis)
    if not integ.step_is_stable(analysis, cfg["dt"]) and not cfg["allow_unstable"]:
        above = integ.stable_again_above(analysis)
        if above < math.inf:  # Choi–Ko's onset band of an unconditionally stable method
            return (
                f"dt={cfg['dt']:g} s is inside the band of steps where Choi–Ko's buckling onset "
                f"load 12·k_b/L² throws this cloth about with {cfg['integrator']} "
                f"({limit:.4g} s < dt < {above:.4g} s; stiffness.bend is a flexural rigidity "
                f"in N·m² in this model): choose dt <= {limit:.4g} or dt >= {above:.4g}, a "
                f"smaller stiffness.bend, or set allow_unstable to true"
            ), limit
        unconditional = ", ".join(
            n
            for n in integrators.available()
            if integrators.get(n).stability is Stability.UNCONDITIONAL
        )
        onset = (
            " (set by Choi–Ko's buckling onset load 12·k_b/L²: stiffness.bend is a flexural "
            "rigidity in N·m² in this model)"
            if limit == analysis.onset_limit
            else ""
        )
        return (
            f"dt={cfg['dt']:g} s is above the stable limit of {cfg['integrator']} for this "
            f"cloth, stable_dt={limit:.4g} s{onset}: choose dt <= {limit:.4g}, an "
            f"unconditionally stable integrator ({unconditional}), or set allow_unstable to "
            f"true"
        ), limit
    return None, limit


def refusal(cfg: dict, model) -> tuple[str | None, tuple[str, ...], float | None]:
    """The checks of a combination of values on ``model``, in the node's order — the thickness
    self-collision needs, the camera, the robot's two topics, a material's bending against the
    method, the method's stable step: ``(reason, the parameters the
    reason names, stable_dt)``; ``reason`` is ``None`` when all pass (``stable_dt`` is known only
    once the stability check has run)."""
    if cfg["self_collision"]:
        try:
            check_thickness(model, cfg["thickness"])
        except ValueError as e:  # a finer cloth (rows, spacing, a scene) can be the cause
            return str(e), ("thickness", "self_collision"), None
    reason = camera_reason(cfg)
    if reason:  # a combination (far above near, look_at away from position)
        return reason, tuple(n for n in SCHEMA if n.startswith("camera.") and n in reason), None
    if cfg["robot.enable"] and _topic(cfg["robot.description_topic"]) == _topic(
        cfg["robot.joint_states_topic"]
    ):
        topic = cfg["robot.joint_states_topic"]
        reason = (
            f"robot.joint_states_topic and robot.description_topic are the same topic {topic!r}: "
            f"a topic has one type (sensor_msgs/JointState, std_msgs/String)"
        )
        return reason, ("robot.joint_states_topic", "robot.description_topic"), None
    if model.bending is not None and not integrators.get(cfg["integrator"]).takes_bending:
        takers = [n for n in integrators.available() if integrators.get(n).takes_bending]
        reason = (
            f"integrator {cfg['integrator']} does not take a material's bending rigidity "
            f"(material {cfg['material'] or 'of the scene'}): choose one of {', '.join(takers)}"
        )
        return reason, ("integrator", "material"), None
    reason, limit = check_stability(cfg, model)
    return reason, (("dt",) if reason else ()), limit


def _topic(name: str) -> str:
    """A topic name without its leading slash (``cloth`` and ``/cloth`` are one topic in the root
    namespace; a stricter check would need the node's namespace)."""
    return name.lstrip("/")


class Refusal(ValueError):
    """A set of values refused as a whole; ``str()`` is the reason, :attr:`named` the parameters it
    names, :attr:`stage` where :func:`check` refused it: ``"applicable"`` (a parameter this
    scene's cloth does not have), ``"model"`` (the model cannot be built) or ``"combination"`` (the
    thickness self-collision needs, the camera, the method's stable step)."""

    def __init__(self, reason: str, named: tuple = (), stage: str = "combination"):
        super().__init__(reason)
        self.named, self.stage = tuple(named), stage


@dataclass(frozen=True)
class Checked:
    """Values checked whole on a scene, and the model they build: what :func:`build` turns into a
    simulator (``stable_dt``: the method's limit on this model and material)."""

    cfg: dict
    scene: Scene
    model: object
    stable_dt: float


#: :func:`check`'s ``changes_from`` for values set on a scene as it loads (a sweep's run)
SCENE_DEFAULTS = "scene defaults"


def check(
    scene: str | Scene,
    values: dict,
    *,
    changes_from: dict | str | None = None,
    model: Callable | None = None,
) -> Checked:
    """One pass from values to what builds a simulator, each step on what the one before checked:

    1. the scene (a name, a path or a loaded :class:`~cloth_sim.scene.Scene`);
    2. every value by the schema, over the scene's defaults (an unknown name is refused);
    3. with ``changes_from`` (the values they change: the node's running ones, or
       :data:`SCENE_DEFAULTS`), a parameter this scene's cloth does not have;
    4. the model they build (``model(cfg, scene)`` when given: the node's cache, or its running
       model);
    5. the combination on that model: the thickness self-collision needs, the camera, the method's
       stable step.

    A single value is refused with :class:`~cloth_sim.parameters.ParameterError`, a set with
    :class:`Refusal`; both name the parameter."""
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    base = defaults(scene)
    cfg = dict(base)
    for name, value in values.items():
        if name not in SCHEMA:
            raise ParameterError(
                name,
                value,
                "a parameter of the node",
                f"{name} is not a parameter; the parameters are {', '.join(sorted(SCHEMA))}",
            )
        cfg[name] = SCHEMA[name].check(value)
    if changes_from is not None:
        before = base if changes_from == SCENE_DEFAULTS else changes_from
        reason = not_applicable(scene, cfg, before)
        if reason:
            raise Refusal(reason, inapplicable_changes(scene, cfg, before), "applicable")
    try:
        built = model(cfg, scene) if model is not None else build_model(cfg, scene)
    except ValueError as e:
        raise Refusal(str(e), (), "model") from None
    refused = device_refusal(cfg, built, scene)
    if refused is not None:
        raise Refusal(*refused)
    reason, named, limit = refusal(cfg, built)
    if reason:
        raise Refusal(reason, named)
    return Checked(cfg, scene, built, limit)


def device_refusal(cfg: dict, model, scene: Scene) -> tuple[str, tuple[str, ...]] | None:
    """Why ``cfg["device"]`` cannot step this cloth here, as ``(reason, the parameters it
    names)``: the device missing (what is, in its words), or a method or a part of the scene it
    does not run (:func:`cloth_sim.backends.refusal`); ``None`` on the cpu."""
    device = cfg["device"]
    if device == "cpu":
        return None
    why = backends.problem(device)
    if why is not None:
        return f"device={device} is refused: {why}", ("device",)
    sweeps = backends.sweeps_colliders(device, cfg["integrator"])
    refused = backends.refusal(
        device,
        cfg["integrator"],
        model,
        strain_limit_method=bool(cfg["strain_limit"]) and cfg["strain_limit_method"] != "provot",
        self_collision=cfg["self_collision"],
        # a robot's links, and the grippers bound to them, sweep over each step (a gripper moved
        # by its pose runs on every device)
        grippers=bool(scene.gripper_links) and not sweeps,
        robot=scene.robot is not None and not sweeps,
    )
    if refused is None:
        return None
    reason, name = refused
    named = ("device",) + ((name,) if name in SCHEMA else ())
    return f"device={device}: {reason}", named


def build(checked: Checked) -> Simulator:
    """The simulator of values :func:`check` accepted."""
    return build_simulator(checked.cfg, checked.model, checked.scene)


def configure(scene: str | Scene, values: dict) -> tuple[dict, Scene, Simulator, float]:
    """``(cfg, scene, simulator, stable_dt)`` for ``scene`` (a name, a path or a loaded scene) with
    ``values`` (parameter name → value) set on it, checked as the node checks a parameter change
    (:func:`check`), then built. A refusal raises ``ValueError``
    (:class:`~cloth_sim.parameters.ParameterError` for a single value) naming the parameter."""
    if not isinstance(scene, Scene):
        scene = load_scene(values.get("scene", scene))
    values = {name: value for name, value in values.items() if name != "scene"}  # loaded above
    checked = check(scene, values, changes_from=SCENE_DEFAULTS)
    return checked.cfg, checked.scene, build(checked), checked.stable_dt
