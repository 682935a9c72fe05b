"""``cloth_sim_node``: the simulator on the ROS graph — a thin adapter over :mod:`cloth_sim`.

Every tick (``publish_rate`` Hz) advances the simulation by ``1/publish_rate`` s in whole steps of
``dt`` (the remainder carries over), then publishes ``~/points`` (organised PointCloud2),
``~/mesh`` (Marker) and ``~/stats``; ``/diagnostics`` at 1 Hz. The messages are built by the pure
functions of :mod:`cloth_sim.ros.messages`.

Parameters (:data:`cloth_sim.parameters.SCHEMA`) are handled as rclpy intends: the pre-set callback
expands a scene change into the scene's values, the on-set callback validates the whole batch with no
side effects (the stability analysis it needs is computed once per material and kept,
:mod:`cloth_sim.stability`), and the post-set callback applies it. A blow-up restores the state
before the failing step and pauses.

The process (:func:`cloth_sim.ros.main`, then :func:`run`) handles SIGINT/SIGTERM itself (rclpy's
handlers are off): a signal at any moment, or two (``ros2 launch`` forwards Ctrl-C), only asks the spin
loop to stop; the node is then destroyed and the process exits 0.
"""

from __future__ import annotations

import collections
import gc
import math
import sys
import time

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import SetParametersResult
from rclpy.exceptions import ParameterException
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import PointCloud2
from std_srvs.srv import SetBool, Trigger
from builtin_interfaces.msg import Time as TimeMsg
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rosgraph_msgs.msg import Clock
from visualization_msgs.msg import Marker, MarkerArray

from .. import integrators
from ..integrators.base import Stability
from .. import stability as stab
from ..parameters import REBUILD, SCHEMA
from ..scene import GRIPPER_NAME, SceneError, load_scene
from ..self_collision import check_thickness
from ..simulator import SimulationDiverged, Simulator, compile_kernels
from . import messages
from . import params as P
from .frames import Frames
from .sim_interfaces import SimulationInterfaces

STATUS_PERIOD = 5.0  # s of wall time between status log lines
WARN_MARGIN = 0.8    # WARN when dt is above this fraction of stable_dt
#: WARN when the real-time factor over the last RTF_WINDOW seconds is below this: "below 1", less
#: the few per cent that timer jitter and whole-step quantisation give a node that keeps up
RTF_WARN = 0.95
RTF_WINDOW = 2.0
#: a tick steps for at most this fraction of its period, so parameters and services are answered
#: in time whatever dt is; what does not fit waits for the next ticks, up to MAX_BACKLOG s of
#: simulated time, and beyond that is dropped (the real-time factor falls below 1, /diagnostics warns).
#: A tick that starts late (the executor was busy) steps that much less, so that it still ends by
#: its own deadline: an overloaded node whose ticks each ran their full budget from a late start
#: drifted past the timer's next period, which rcl then skips (gaps of 3–4 periods in the fuzz).
TICK_BUDGET = 0.8
MAX_BACKLOG = 0.25
#: with real_time_factor 0 a tick steps until its budget is spent, at most this many steps
MAX_STEPS_PER_TICK = 1_000_000
#: the most steps one ~/step request may ask for (the node answers nothing else meanwhile)
MAX_STEP_REQUEST = 100_000
#: a publish_rate is refused only when the measured cost exceeds the time available this many times
RATE_REFUSAL_LOAD = 10.0
#: recovery checkpoints: one every CHECKPOINT_EVERY s of simulated time, the last CHECKPOINTS kept
CHECKPOINT_EVERY = 0.1
CHECKPOINTS = 20
#: the rebuild parameters that shape the model (``scene`` is the other one)
MODEL_KEYS = tuple(name for name in REBUILD if name != "scene")


class StartupError(ValueError):
    """A value the node cannot start with; one line naming it."""


def _settle_garbage() -> None:
    """Collect once and move every object alive now to the collector's permanent generation.

    Python's full (generation-2) collection walks every tracked object: after start-up (rclpy,
    numba, scipy, the model) that is ~140,000 objects and 30–75 ms, which, whenever the collector
    chose to run it, stalled a tick by 2–4 periods at 60 Hz. Frozen objects are not walked, so a
    later full collection only sees what was made since. Called at start-up and after a rebuild
    (the objects a new simulation keeps); garbage is collected first, so nothing collectable is
    frozen."""
    gc.collect()
    gc.freeze()


def _stats_type():
    from cloth_sim.msg import Stats  # generated from msg/Stats.msg by rosidl

    return Stats


def _srv_types():
    from cloth_sim.srv import Grasp, Release, Step  # generated from srv/ by rosidl

    return Grasp, Release, Step


def _material(model, cfg: dict) -> tuple[np.ndarray, np.ndarray]:
    """Per-spring stiffness and damping of ``model`` from the family parameters in ``cfg``."""
    k = np.array([cfg[f"stiffness.{f}"] for f in model.family_names])[model.family]
    c = np.array([cfg[f"damping.{f}"] for f in model.family_names])[model.family]
    return k, c


def _as_declared(p: Parameter) -> Parameter:
    """An integer given for a double parameter (``ros2 param set /cloth_sim dt 1``), as a double, and
    an integer array for a double array (``gravity: [0, 0, -9]`` in a params file), as a double
    array: the schema accepts them, rclpy's type check would not (its refusal names no parameter)."""
    spec = SCHEMA.get(p.name)
    if spec is not None and spec.type is float and p.type_ == Parameter.Type.INTEGER:
        return Parameter(p.name, value=float(p.value))
    if spec is not None and spec.type == "vector3" and p.type_ == Parameter.Type.INTEGER_ARRAY:
        return Parameter(p.name, value=[float(v) for v in p.value])
    return p


def _wind(cfg: dict):
    w = cfg["wind.strength"] * np.asarray(cfg["wind.direction"], dtype=float)
    return w if np.any(w) else None


class ClothSimNode(Node):
    """The ``cloth_sim`` node. ``parameter_overrides`` etc. are passed to :class:`rclpy.node.Node`."""

    def __init__(self, **kwargs):
        super().__init__("cloth_sim", **kwargs)
        self._ready = False
        self.Stats = _stats_type()
        self._parameter_overrides = {n: _as_declared(p) for n, p in self._parameter_overrides.items()}
        overrides = {name: p.value for name, p in self._parameter_overrides.items()}
        # the scene first: it provides the other parameters' defaults
        scene_name = self._startup_value("scene", overrides.get("scene", "hanging"))
        try:
            self.scene = load_scene(scene_name)
        except SceneError as e:
            raise StartupError(f"scene: {e}") from None
        defaults = P.defaults(self.scene)
        self.cfg = {}
        for name in SCHEMA:
            value = self._startup_value(name, overrides.get(name, defaults[name]))
            try:
                self.declare_parameter(name, defaults[name] if name != "scene" else scene_name,
                                       P.descriptor(SCHEMA[name]))
            except ParameterException:  # e.g. an integer given for a double: rclpy's types are strict
                raise StartupError(f"{name} = {overrides.get(name)!r} is not accepted: expected "
                                   f"{SCHEMA[name].range_text()}, as a ROS "
                                   f"{P.type_name(SCHEMA[name])} (write 1.0, not 1, for a "
                                   f"double)") from None
            self.cfg[name] = value
        self._models = {}  # rebuild key -> model (a scene's model at a size), last few kept
        self._validated = None  # what the on-set callback checked, for the post-set callback
        model = self._model(self.cfg, self.scene)
        reason, self._stable_dt = self._check_stability(self.cfg, model)
        if reason:
            raise StartupError(reason)
        if self.cfg["self_collision"]:
            try:
                check_thickness(model, self.cfg["thickness"])
            except ValueError as e:
                raise StartupError(str(e)) from None
        self.sim = self._build_simulator(self.cfg, model, self.scene)
        # every kernel compiled (or loaded from numba's cache) now, not in the tick that first
        # needs it: switching to kang live once stalled the node for 6 s
        kernels = compile_kernels()

        self.paused = False
        self.error: str | None = None
        self.overruns = 0
        self._carry = 0.0
        self._next_tick = None  # perf_counter time the next tick is due (the budget's deadline)
        self._last_tick = None  # perf_counter time the last tick started
        self._resync = False  # the next tick's deadline is not on its timer's grid (a new rate)
        self._history = collections.deque()  # (wall, sim time) over the last RTF_WINDOW s
        self._tick_costs = collections.deque(maxlen=120)  # (steps, step wall, publish wall)
        self._last_status = time.monotonic()
        self._rates_run = {self.cfg["publish_rate"]}  # rates the node has run with: never refused
        self._gate_errors: list[str] = []  # found by the pre-set callback, reported by on-set
        self._checkpoints = collections.deque(maxlen=CHECKPOINTS)  # (sim time, saved state)
        self._change_checkpoint = None  # the state before the last accepted live change
        self.dropped = 0.0  # simulated seconds dropped by ticks over their budget

        self.points_pub = self.create_publisher(PointCloud2, "~/points", 10)
        self.mesh_pub = self.create_publisher(Marker, "~/mesh", 10)
        self.stats_pub = self.create_publisher(self.Stats, "~/stats", 10)
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.colliders_pub = self.create_publisher(MarkerArray, "~/colliders", 10)
        self._pose_subs = []
        #: (kind, key) -> (position, orientation) to reach over the next tick: kind "collider"
        #: (key: its index) or "gripper" (key: its name)
        self._pose_targets = {}
        self._subscribe_colliders()
        self._grippers = {}  # name -> (its pose subscription, its wrench publisher)
        self._adopt_grippers()
        self.clock_pub = None
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.create_service(SetBool, "~/pause", self._on_pause)
        Grasp, Release, Step = _srv_types()
        self.create_service(Grasp, "~/grasp", self._on_grasp)
        self.create_service(Release, "~/release", self._on_release)
        self.create_service(Step, "~/step", self._on_step)
        self.interfaces = SimulationInterfaces(self)  # the ROS simulation standard's services
        self.frames = Frames(self)  # TF
        self.frames.publish_static(self.cfg["world_frame_id"], self.cfg["frame_id"])
        self.add_pre_set_parameters_callback(self._pre_set)
        self.add_on_set_parameters_callback(self._on_set)
        self.add_post_set_parameters_callback(self._post_set)
        self.timer = self.create_timer(1.0 / self.cfg["publish_rate"], self._tick)
        self.diag_timer = self.create_timer(1.0, self._publish_diagnostics)
        self._ready = True
        _settle_garbage()
        self.get_logger().info(
            f"scene {self.scene.name}: {self.cloth_text()}, "
            f"{self.sim.integrator}, dt={self.sim.dt:g} s, {self.cfg['publish_rate']:g} Hz, "
            f"terms: {', '.join(self.sim.active_terms)}; kernels ready in {kernels:.2f} s")

    @staticmethod
    def _startup_value(name, value):
        value, reason = P.check_value(name, value)
        if reason:
            raise StartupError(reason)
        return value

    # ------------------------------------------------------------------ building
    def _model(self, cfg: dict, scene):
        """The model for ``cfg``'s rebuild values (kept: validation and application share it)."""
        key = (scene.source, *(cfg[k] for k in MODEL_KEYS))
        model = self._models.get(key)
        if model is None:
            size = ({"density": cfg["density"]} if scene.mesh is not None else
                    {k: cfg[k] for k in ("rows", "cols", "spacing", "particle_mass")})
            model = scene.build_model(**size, model=cfg["model"],
                                      stiffness={f: cfg[f"stiffness.{f}"] for f in scene.families},
                                      damping={f: cfg[f"damping.{f}"] for f in scene.families})
            if len(self._models) >= 4:
                self._models.pop(next(iter(self._models)))
            self._models[key] = model
        return model

    @staticmethod
    def _build_simulator(cfg: dict, model, scene) -> Simulator:
        sim = Simulator(model, integrator=cfg["integrator"], dt=cfg["dt"], gravity=cfg["gravity"],
                        wind=_wind(cfg), drag=cfg["drag"], strain_limit=cfg["strain_limit"] or None,
                        strain_limit_passes=cfg["strain_limit_passes"],
                        colliders=scene.make_colliders(), thickness=cfg["thickness"],
                        self_collision=cfg["self_collision"])
        scene.apply_grippers(sim)
        k, c = _material(model, cfg)
        if not (np.array_equal(model.stiffness, k) and np.array_equal(model.damping, c)):
            for f in model.family_names:  # a kept model built with other values: set them
                sim.set_stiffness(f, cfg[f"stiffness.{f}"])
                sim.set_damping(f, cfg[f"damping.{f}"])
        return sim

    @staticmethod
    def _check_stability(cfg: dict, model) -> tuple[str | None, float]:
        """``(reason, stable_dt)``: the limit of ``cfg``'s method on ``model`` with ``cfg``'s
        material (computed once per material and method, :mod:`cloth_sim.stability`), and the
        reason to refuse ``cfg["dt"]`` above it (``None`` when fine or ``allow_unstable``)."""
        k, c = _material(model, cfg)
        analysis = stab.analysis_for(model, k, c, cfg["drag"])
        integ = integrators.get(cfg["integrator"])(model)
        limit = integ.stable_dt(analysis)
        if not integ.step_is_stable(analysis, cfg["dt"]) and not cfg["allow_unstable"]:
            above = integ.stable_again_above(analysis)
            if above < math.inf:  # Choi–Ko's onset band of an unconditionally stable method
                return (f"dt={cfg['dt']:g} s is inside the band of steps where Choi–Ko's buckling onset "
                        f"load 12·k_b/L² throws this cloth about with {cfg['integrator']} "
                        f"({limit:.4g} s < dt < {above:.4g} s; stiffness.bend is a flexural rigidity "
                        f"in N·m² in this model): choose dt <= {limit:.4g} or dt >= {above:.4g}, a "
                        f"smaller stiffness.bend, or set allow_unstable to true"), limit
            unconditional = ", ".join(n for n in integrators.available()
                                      if integrators.get(n).stability is Stability.UNCONDITIONAL)
            onset = (" (set by Choi–Ko's buckling onset load 12·k_b/L²: stiffness.bend is a flexural "
                     "rigidity in N·m² in this model)" if limit == analysis.onset_limit else "")
            return (f"dt={cfg['dt']:g} s is above the stable limit of {cfg['integrator']} for this "
                    f"cloth, stable_dt={limit:.4g} s{onset}: choose dt <= {limit:.4g}, an "
                    f"unconditionally stable integrator ({unconditional}), or set allow_unstable to "
                    f"true"), limit
        return None, limit

    # ------------------------------------------------------------------ parameters
    def _pre_set(self, parameters: list[Parameter]) -> list[Parameter]:
        """The gate every value passes first (it runs before rclpy's own type and range checks,
        whose refusals do not name the parameter): a value the schema refuses is noted, and stands
        in the batch as the parameter's current value, so that the on-set callback refuses the batch
        with the schema's reason. A scene change brings the scene's values for every parameter the
        batch does not set."""
        self._gate_errors = []
        gated = []
        for p in parameters:
            reason = self._gate(p)
            if reason:
                self._gate_errors.append(reason)
                # a stand-in that passes rclpy's checks, so the on-set callback gives the reason
                # (an unknown name would raise before it, with an empty list in rclpy 7.1's text)
                gated.append(self.get_parameter(p.name if self.has_parameter(p.name) else "frame_id"))
                continue
            gated.append(_as_declared(p))
        parameters = gated
        if self._gate_errors:
            return parameters
        scene = next((p for p in parameters if p.name == "scene"), None)
        if scene is None or scene.value == self.cfg["scene"] or not isinstance(scene.value, str):
            return parameters
        try:
            new = load_scene(scene.value)
        except SceneError:
            return parameters  # the on-set callback refuses it with the reason
        named = {p.name for p in parameters}
        return list(parameters) + [Parameter(k, value=v) for k, v in P.scene_values(new).items()
                                   if k not in named]

    def _gate(self, p: Parameter) -> str | None:
        """The schema's reason to refuse ``p`` (or the declared type's, for rclpy's own
        parameters), ``None`` when it may go on."""
        if not self.has_parameter(p.name):
            return (f"{p.name} is not a parameter of this node; its parameters are "
                    f"{', '.join(sorted(SCHEMA))}")
        if p.type_ == Parameter.Type.NOT_SET:
            return f"{p.name} cannot be unset"
        if p.name in SCHEMA:
            return P.check_value(p.name, p.value)[1]
        declared = self.describe_parameter(p.name)
        if not declared.dynamic_typing and declared.type != p.type_.value:
            return (f"{p.name} = {p.value!r} is not accepted: expected a "
                    f"{Parameter.Type(declared.type).name.lower()}")
        return None

    def _on_set(self, parameters: list[Parameter]) -> SetParametersResult:
        """Validate the whole batch; nothing changes here (the post-set callback applies it)."""
        if not self._ready:
            return SetParametersResult(successful=True)
        self._validated = None
        if self._gate_errors:
            reason, self._gate_errors = "; ".join(self._gate_errors), []
            return SetParametersResult(successful=False, reason=reason)
        cand = dict(self.cfg)
        for p in parameters:
            if p.name not in SCHEMA:
                continue
            value, reason = P.check_value(p.name, p.value)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
            cand[p.name] = value
        if cand == self.cfg:
            self._validated = (cand, None, None, self._stable_dt)
            return SetParametersResult(successful=True)
        scene = self.scene
        try:
            if cand["scene"] != self.cfg["scene"]:
                scene = load_scene(cand["scene"])
            reason = P.not_applicable(scene, cand, self.cfg)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
            rebuild = scene is not self.scene or any(cand[k] != self.cfg[k] for k in MODEL_KEYS)
            model = self._model(cand, scene) if rebuild else self.sim.model
        except (SceneError, ValueError) as e:  # e.g. a scene whose file changed since
            return SetParametersResult(successful=False, reason=f"scene: {e}")
        if cand["publish_rate"] not in self._rates_run:
            reason = self._check_rate(cand)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        if cand["self_collision"]:
            try:
                check_thickness(model, cand["thickness"])
            except ValueError as e:  # a finer cloth (rows, spacing, a scene) can be the cause
                reason = self._blame(parameters, cand, str(e), ("thickness", "self_collision"))
                return SetParametersResult(successful=False, reason=reason)
        reason, limit = self._check_stability(cand, model)
        if reason:  # the refusal names what made the limit fall, as well as dt
            return SetParametersResult(successful=False,
                                       reason=self._blame(parameters, cand, reason, ("dt",)))
        self._validated = (cand, scene if rebuild else None, model if rebuild else None, limit)
        return SetParametersResult(successful=True)

    def _blame(self, parameters, cand: dict, reason: str, named: tuple) -> str:
        """``reason`` for a refusal of a combination, prefixed with the other values of the
        request that changed (``reason`` names ``named`` itself)."""
        changed = [p.name for p in parameters if p.name in SCHEMA and p.name not in named
                   and cand[p.name] != self.cfg[p.name]]
        if not changed:
            return reason
        return (f"{', '.join(f'{n} = {cand[n]!r}' for n in changed)}: with "
                f"{'this value' if len(changed) == 1 else 'these values'}, {reason}")

    def _post_set(self, parameters: list[Parameter]) -> None:
        """Apply what :meth:`_on_set` accepted."""
        if not self._ready or self._validated is None:
            return
        cand, scene, model, limit = self._validated
        self._validated = None
        if scene is not None:
            self.sim = self._build_simulator(cand, model, scene)
            self.scene = scene
            self.interfaces.spawned.clear()  # the new simulation has the scene's colliders only
            self._drop_grippers()
            self._adopt_grippers()
            self._subscribe_colliders()
            self._carry = 0.0
            self._history.clear()
            self._checkpoints.clear()
            self._change_checkpoint = None
            _settle_garbage()
        else:
            if cand != self.cfg:
                self._change_checkpoint = (self.sim.time, self.sim.save_state())
            self._apply_live(cand)
        if cand["real_time_factor"] != self.cfg["real_time_factor"]:
            self._carry = 0.0  # a backlog owed at the old pace is not owed at the new one
            self._history.clear()
        self._rates_run.add(cand["publish_rate"])
        rate_changed = cand["publish_rate"] != self.cfg["publish_rate"]
        self.cfg = cand
        self._stable_dt = limit
        self.frames.publish_static(cand["world_frame_id"], cand["frame_id"])
        if rate_changed:
            self.timer.cancel()
            self.destroy_timer(self.timer)
            self.timer = self.create_timer(1.0 / cand["publish_rate"], self._tick)
            # the new timer's first tick comes a full new period from now; it is due a period
            # after the last one, so it steps that much less (its budget's deadline) and the
            # ~/stats interval across the change stays under 1.8 new periods (it reached 2)
            self._next_tick = (None if self._last_tick is None
                               else self._last_tick + 1.0 / cand["publish_rate"])
            self._resync = True

    def _apply_live(self, cand: dict) -> None:
        sim, cur = self.sim, self.cfg
        for f in sim.model.family_names:
            if cand[f"stiffness.{f}"] != cur[f"stiffness.{f}"]:
                sim.set_stiffness(f, cand[f"stiffness.{f}"])
            if cand[f"damping.{f}"] != cur[f"damping.{f}"]:
                sim.set_damping(f, cand[f"damping.{f}"])
        if cand["integrator"] != sim.integrator:
            sim.set_integrator(cand["integrator"])
        if cand["dt"] != sim.dt:
            sim.dt = cand["dt"]
        if cand["gravity"] != cur["gravity"]:
            sim.gravity = cand["gravity"]
        if (cand["wind.strength"], cand["wind.direction"]) != (cur["wind.strength"],
                                                              cur["wind.direction"]):
            sim.wind = _wind(cand)
        if cand["drag"] != cur["drag"]:
            sim.drag = cand["drag"]
        if cand["strain_limit"] != cur["strain_limit"]:
            sim.strain_limit = cand["strain_limit"] or None
        if cand["strain_limit_passes"] != cur["strain_limit_passes"]:
            sim.strain_limit_passes = cand["strain_limit_passes"]
        if cand["thickness"] != cur["thickness"]:
            sim.thickness = cand["thickness"]
        if cand["self_collision"] != cur["self_collision"]:
            sim.self_collision = cand["self_collision"]

    def _check_rate(self, cand: dict) -> str | None:
        """A rate is refused only when the measured cost of stepping and publishing exceeds the
        time available many times over (RATE_REFUSAL_LOAD): measured costs are noisy, and a tick
        that does not fit only lowers the real-time factor (ticks are bounded, /diagnostics warns).
        A rate the node has run with is never refused."""
        if len(self._tick_costs) < 10:
            return None
        steps = sum(c[0] for c in self._tick_costs)
        step_wall = sum(c[1] for c in self._tick_costs)
        pub_wall = sum(c[2] for c in self._tick_costs) / len(self._tick_costs)
        per_step = step_wall / steps if steps else 0.0
        load = per_step / cand["dt"] + cand["publish_rate"] * pub_wall
        if load > RATE_REFUSAL_LOAD:
            return (f"publish_rate={cand['publish_rate']:g} Hz cannot be met: stepping "
                    f"({1e3 * per_step:.3f} ms/step at dt={cand['dt']:g}) and publishing "
                    f"({1e3 * pub_wall:.3f} ms/tick) would need {load:.2f} s of work per second; "
                    f"lower publish_rate, or raise dt")
        return None

    def stable_dt(self) -> float:
        """The current method's stable_dt (``inf`` for unconditionally stable methods)."""
        return self._stable_dt

    # ------------------------------------------------------------------ services
    def reset_simulation(self, keep_paused: bool = False) -> None:
        """The scene's initial shape at rest, time 0, its own grippers holding again; running
        afterwards unless ``keep_paused`` (``~/reset`` runs, the standard's reset keeps the state)."""
        self.sim.reset()  # releases every gripper
        self._drop_grippers()
        self.scene.apply_grippers(self.sim)  # the scene's own grippers hold again
        self._adopt_grippers()
        self._checkpoints.clear()
        self._change_checkpoint = None
        self._carry = 0.0
        self._history.clear()
        self.error = None
        if not keep_paused:
            self.paused = False
            self.interfaces.stopped = False

    def set_paused(self, paused: bool) -> None:
        if not paused and self.error:
            self.error = None  # the user un-pauses after a blow-up: try again from the good state
        self.paused = bool(paused)
        if not paused:
            self.interfaces.stopped = False
        self._history.clear()

    def _on_reset(self, request, response):
        self.reset_simulation()
        response.success = True
        response.message = f"reset {self.scene.name} to its initial shape at rest, time 0"
        return response

    def _on_pause(self, request, response):
        self.set_paused(bool(request.data))
        response.success = True
        response.message = "paused" if self.paused else "running"
        return response

    # ------------------------------------------------------------------ tick
    def _tick(self) -> None:
        t0 = time.perf_counter()
        period = 1.0 / self.cfg["publish_rate"]
        # how late this tick starts against the period grid of the previous ones
        expected = self._next_tick
        late = t0 - expected if expected is not None and t0 > expected else 0.0
        self._next_tick = (expected + period if expected is not None and late < period
                           and not self._resync else t0 + period)
        self._last_tick, self._resync = t0, False
        sim = self.sim
        steps, step_max, step_wall = 0, 0.0, 0.0
        if not self.paused:
            target = self.cfg["real_time_factor"]
            budget = max(0.25 * period, TICK_BUDGET * period - late)
            if target > 0:
                self._carry += period * target
                n = int(math.floor(self._carry / sim.dt + 1e-9))
                self._carry -= n * sim.dt
            else:  # as fast as the CPU allows: steps until the tick's budget is spent
                n, self._carry = MAX_STEPS_PER_TICK, 0.0
            try:
                steps, step_wall, step_max = self._advance(n, t0, budget)
                if target > 0:
                    self._carry += (n - steps) * sim.dt  # what did not fit waits for the next ticks
                    if self._carry > MAX_BACKLOG * max(target, 1.0):
                        self.dropped += self._carry - MAX_BACKLOG * max(target, 1.0)
                        self._carry = MAX_BACKLOG * max(target, 1.0)
                self._keep_checkpoint()
            except SimulationDiverged as e:
                self._recover(e)
        elif self.interfaces.busy:  # a simulate_steps goal steps the paused simulation
            budget = max(0.25 * period, TICK_BUDGET * period - late)
            steps, step_wall, step_max = self.interfaces.tick(t0, budget)
        self._publish(t0, steps, step_wall, step_max)
        if time.perf_counter() - t0 > period:
            self.overruns += 1

    def _advance(self, n: int, t0: float, budget: float) -> tuple[int, float, float]:
        """Up to ``n`` steps, stopping once ``budget`` s have passed since ``t0``; poses received
        for colliders and grippers are reached over them. Returns ``(steps, step wall, longest)``."""
        sim = self.sim
        moves = self._pose_moves() if self._pose_targets and n else None
        steps, step_wall, step_max = 0, 0.0, 0.0
        span = n if n < MAX_STEPS_PER_TICK else max(1, int(budget / max(self._step_cost(), 1e-6)))
        for k in range(n):
            if moves:  # a pose received since the last tick: reached over this tick's steps
                f = min(1.0, (k + 1) / span)
                for (kind, key), (p0, q0, p1, q1) in moves.items():
                    q = (1 - f) * q0 + f * q1
                    q /= np.linalg.norm(q)
                    if kind == "collider":
                        sim.set_collider_pose(key, (1 - f) * p0 + f * p1, q)
                    else:  # _pose_moves kept only grippers that hold; none is released mid-tick
                        sim.set_gripper_pose(key, (1 - f) * p0 + f * p1, q)
                if f >= 1.0:
                    moves = None
            s0 = time.perf_counter()
            sim.step()
            el = time.perf_counter() - s0
            step_wall += el
            step_max = max(step_max, el)
            steps += 1
            # stop before a step that would end past the budget, predicting its cost by the last
            # one's: a tick then overruns only when a step takes longer than the one before it
            if s0 + 2.0 * el - t0 > budget:
                break
        if moves:  # the tick ended before the poses were reached: the rest next tick
            for (kind, key), (_, _, p1, q1) in moves.items():
                self._pose_targets.setdefault((kind, key), (p1, q1))
        return steps, step_wall, step_max

    def _step_cost(self) -> float:
        costs = [w / s for s, w, _ in self._tick_costs if s]
        return float(np.median(costs)) if costs else 1e-4

    def stamp(self):
        return self._stamp()

    def _stamp(self):
        """The messages' stamp: the simulated time with ``publish_clock``, else the node's clock."""
        if self.cfg["publish_clock"]:
            t = self.sim.time
            sec = math.floor(t)
            return TimeMsg(sec=int(sec), nanosec=min(int(round((t - sec) * 1e9)), 999_999_999))
        return self.get_clock().now().to_msg()

    def _publish(self, t0: float, steps: int, step_wall: float, step_max: float) -> None:
        """Everything a tick (or ``~/step``) publishes: /clock, the cloud, mesh, markers, wrenches,
        stats."""
        sim = self.sim
        t1 = time.perf_counter()
        stamp = self._stamp()
        frame = self.cfg["frame_id"]
        if self.cfg["publish_clock"]:
            if self.clock_pub is None:
                self.clock_pub = self.create_publisher(Clock, "/clock", 10)
            self.clock_pub.publish(Clock(clock=stamp))
        if self.points_pub.get_subscription_count() > 0:
            self.points_pub.publish(self.point_cloud(stamp))
        if self.mesh_pub.get_subscription_count() > 0:
            self.mesh_pub.publish(messages.mesh_bytes(sim.positions, sim.model.triangles, frame, stamp))
        if (sim.colliders or self._grippers) and self.colliders_pub.get_subscription_count() > 0:
            grippers = {name: sim.gripper_pose(name)[0] for name in self._grippers}
            self.colliders_pub.publish(messages.collider_markers(sim.colliders, frame, stamp, grippers))
        for name, (_, pub) in self._grippers.items():
            force, torque = sim.gripper_wrench(name)
            pub.publish(messages.wrench(force, torque, frame, stamp))
        self.frames.publish(sim, frame, stamp)
        wall_now = time.monotonic()
        self._history.append((wall_now, sim.time))
        while self._history and wall_now - self._history[0][0] > RTF_WINDOW:
            self._history.popleft()
        self.stats_pub.publish(messages.stats(
            self.Stats, stamp=stamp, frame_id=frame, integrator=sim.integrator, dt=sim.dt,
            steps=steps, step_wall=step_wall, step_max=step_max,
            tick_wall=time.perf_counter() - t0, rtf=self.real_time_factor(), sim_time=sim.time,
            energy=sim.energy(), max_strain=sim.max_strain(), overruns=self.overruns,
            stable_dt=self._stable_dt, paused=self.paused))
        self._tick_costs.append((steps, step_wall, time.perf_counter() - t1))
        if wall_now - self._last_status >= STATUS_PERIOD:
            self._last_status = wall_now
            self.get_logger().info(self.status_line())

    # ------------------------------------------------------------------ manipulation
    def _on_grasp(self, request, response):
        p = request.point
        name = request.gripper
        response.success, response.count = False, 0
        if not GRIPPER_NAME.fullmatch(name or ""):  # the same rule as a scene's gripper names
            response.message = (f"gripper = {name!r}: expected a name of ASCII letters, digits and _ "
                                f"(not starting with a digit, at most 64); it names its topics")
            return response
        try:
            idx = self.sim.grasp(name, (p.x, p.y, p.z), request.radius)
        except ValueError as e:
            response.message = str(e)
            return response
        self._gripper_topics(name)
        response.success, response.count = True, len(idx)
        response.message = f"gripper {name!r} holds {len(idx)} particles"
        return response

    def _gripper_topics(self, name: str) -> None:
        pose_sub = self.create_subscription(
            PoseStamped, f"~/grippers/{name}/pose",
            lambda msg, name=name: self._on_pose(("gripper", name), f"~/grippers/{name}/pose", msg), 10)
        wrench_pub = self.create_publisher(WrenchStamped, f"~/grippers/{name}/wrench", 10)
        self._grippers[name] = (pose_sub, wrench_pub)

    def _adopt_grippers(self) -> None:
        """Topics for the grippers the scene declares (the simulator holds with them already)."""
        for name in self.sim.grippers:
            if name not in self._grippers:
                self._gripper_topics(name)

    def release_gripper(self, name: str) -> None:
        """Let go with gripper ``name`` and drop its topics (``ValueError`` for an unknown one)."""
        self.sim.release(name)
        sub, pub = self._grippers.pop(name)
        self.destroy_subscription(sub)
        self.destroy_publisher(pub)
        self._pose_targets.pop(("gripper", name), None)

    def _on_release(self, request, response):
        name = request.gripper
        try:
            self.release_gripper(name)
        except ValueError as e:
            response.success, response.message = False, str(e)
            return response
        response.success, response.message = True, f"gripper {name!r} released"
        return response

    def _drop_grippers(self) -> None:
        """A rebuild or a reset: the grippers' particles are gone or back in place; so are they."""
        for sub, pub in self._grippers.values():
            self.destroy_subscription(sub)
            self.destroy_publisher(pub)
        self._grippers = {}
        self._pose_targets = {k: v for k, v in self._pose_targets.items() if k[0] != "gripper"}

    def step_paused(self, n: int) -> tuple[bool, str]:
        """Exactly ``n`` steps now, while paused (``~/step``, the standard's ``step_simulation``);
        ``(success, message)``. A blow-up goes back and stays paused, as in a tick."""
        if not self.paused:
            return False, "~/step runs only while paused: call ~/pause with data: true first"
        if n > MAX_STEP_REQUEST or n < 0:
            return False, (f"steps = {n} is not accepted: expected an integer in "
                           f"[0, {MAX_STEP_REQUEST}] (the node answers nothing else while it steps)")
        t0 = time.perf_counter()
        try:
            steps, wall, longest = self._advance(int(n), t0, math.inf)
        except SimulationDiverged as e:
            self._recover(e)
            return False, self.error or str(e)
        self._publish(t0, steps, wall, longest)
        return True, f"{steps} steps"

    def step_within(self, n: int, t0: float, budget: float) -> tuple:
        """Up to ``n`` steps while paused within a tick's ``budget`` (the standard's
        ``simulate_steps``): ``(steps, step wall, longest, None)``, or ``(None, 0, 0, message)``
        after a blow-up (the node went back and paused)."""
        try:
            return (*self._advance(int(n), t0, budget), None)
        except SimulationDiverged as e:
            self._recover(e)
            return None, 0.0, 0.0, self.error or str(e)

    def _on_step(self, request, response):
        response.success, response.message = self.step_paused(int(request.steps))
        response.sim_time = self.sim.time
        return response

    # ------------------------------------------------------------------ colliders
    def _subscribe_colliders(self) -> None:
        """``~/colliders/<name>/pose`` for each collider of the current scene (again after a
        scene change)."""
        for sub in self._pose_subs:
            self.destroy_subscription(sub)
        self._pose_subs = []
        self._pose_targets = {k: v for k, v in self._pose_targets.items() if k[0] != "collider"}
        for i, c in enumerate(self.sim.colliders):
            topic = f"~/colliders/{c.name}/pose"
            self._pose_subs.append(self.create_subscription(
                PoseStamped, topic, lambda msg, i=i, topic=topic: self._on_pose(("collider", i), topic, msg),
                10))

    def colliders_changed(self) -> None:
        """After a collider was spawned or deleted: the pose topics follow the new list."""
        self._subscribe_colliders()

    def _on_pose(self, key, topic: str, msg) -> None:
        """A new pose for a collider or a gripper: checked here (a bad one is logged, naming the
        field, and ignored), reached over the next tick's steps (its velocity is the pose change
        over them)."""
        position, orientation, problem = messages.checked_pose(msg.pose, msg.header.frame_id,
                                                               self.cfg["frame_id"])
        if problem:
            self.get_logger().warning(f"{topic} ignored: {problem}", throttle_duration_sec=1.0)
            return
        self._pose_targets[key] = (position, orientation)

    def _pose_moves(self) -> dict:
        """``{key: (p0, q0, p1, q1)}``: from where each moved collider or gripper is to its target
        (the quaternion's sign chosen for the shorter way)."""
        moves, sim = {}, self.sim
        for (kind, key), (p1, q1) in self._pose_targets.items():
            if kind == "collider":
                c = sim.colliders[key]
                p0, q0 = c.position.copy(), c.orientation.copy()
            elif key in sim.grippers:
                p0, q0 = sim.gripper_pose(key)
            else:
                continue
            if float(q0 @ q1) < 0:
                q1 = -q1
            moves[(kind, key)] = (p0, q0, p1, q1)
        self._pose_targets = {}
        return moves

    def _keep_checkpoint(self) -> None:
        if not self._checkpoints or self.sim.time - self._checkpoints[-1][0] >= CHECKPOINT_EVERY:
            self._checkpoints.append((self.sim.time, self.sim.save_state()))

    def _recover(self, error: SimulationDiverged) -> None:
        """Pause after a blow-up, back at a state from before the run-away began: the one saved
        before the last parameter change when that came within the last second of simulated time
        (a dt or stiffness that does not hold diverges within a few steps, and the steps in
        between are already running away), else the oldest kept checkpoint (up to 2 s back). A
        stable dt and ``~/pause false`` then resume from there."""
        sim = self.sim
        candidates = [c for c in (self._change_checkpoint,) if c and sim.time - c[0] <= 1.0]
        candidates += list(self._checkpoints)[:1]
        if candidates:
            when, saved = candidates[0]
            sim.restore_state(saved)
        self._checkpoints.clear()
        self._change_checkpoint = None
        self.error = str(error)
        self.paused = True
        self._carry = 0.0
        self.get_logger().error(f"{error} Went back to t={sim.time:.3f} s and paused: fix the "
                                f"parameters, then call ~/pause with data=false, or ~/reset.")
        self._publish_diagnostics()

    def point_cloud(self, stamp) -> PointCloud2:
        rows, cols = self.cloud_shape()
        return messages.point_cloud(self.sim.positions, rows, cols,
                                    self.cfg["frame_id"], stamp)

    def cloud_shape(self) -> tuple[int, int]:
        """``~/points``' height and width: the grid's rows and columns, or 1 × vertices (a mesh's
        cloud is unorganised)."""
        model = self.sim.model
        return (model.rows, model.cols) if model.rows else (1, model.n_particles)

    def cloth_text(self) -> str:
        """``32×32 provot`` or ``mesh tshirt.obj (1234 vertices, 2300 triangles) provot``."""
        model = self.sim.model
        if model.rows:
            return f"{model.rows}×{model.cols} {model.model}"
        return (f"mesh {self.scene.mesh['file'].name} ({model.n_particles} vertices, "
                f"{len(model.triangles)} triangles) {model.model}")

    def real_time_factor(self) -> float:
        if len(self._history) < 2:
            return 0.0 if self.paused else 1.0
        (w0, s0), (w1, s1) = self._history[0], self._history[-1]
        return (s1 - s0) / (w1 - w0) if w1 > w0 else 0.0

    def status_line(self) -> str:
        state = "PAUSED " if self.paused else ""
        return (f"{state}t={self.sim.time:.2f} s  {self.sim.integrator}  dt={self.sim.dt:g} s  "
                f"rtf={self.real_time_factor():.2f}  max_strain={self.sim.max_strain():+.4f}  "
                f"overruns={self.overruns}")

    def diagnostic_status(self):
        sim = self.sim
        rtf = self.real_time_factor()
        values = {
            "integrator": sim.integrator, "dt": f"{sim.dt:g}", "stable_dt": f"{self._stable_dt:.6g}",
            "real_time_factor": f"{rtf:.3f}", "sim_time": f"{sim.time:.4f}",
            "particles": sim.model.n_particles, "max_strain": f"{sim.max_strain():.5f}",
            "overruns": self.overruns, "paused": str(self.paused).lower(),
            "publish_rate": f"{self.cfg['publish_rate']:g}", "scene": self.scene.name,
            "dropped_sim_time": f"{self.dropped:.4f}",
            "target_real_time_factor": f"{self.cfg['real_time_factor']:g}",
            "grippers": ", ".join(self._grippers) or "none",
        }
        return messages.diagnostic_status(
            error=self.error, paused=self.paused, rtf=rtf, rtf_known=len(self._history) >= 2,
            rtf_warn=RTF_WARN * self.cfg["real_time_factor"], dt=sim.dt, stable_dt=self._stable_dt, warn_margin=WARN_MARGIN,
            values=values)

    def _publish_diagnostics(self) -> None:
        self.diag_pub.publish(messages.diagnostic_array(self.diagnostic_status(),
                                                        self.get_clock().now().to_msg()))


# ---------------------------------------------------------------------- process
def run(argv, stop) -> int:
    """Spin the node until ``stop`` (a :class:`cloth_sim.ros.StopRequest`, installed by
    :func:`cloth_sim.ros.main` before anything heavy is imported) says a signal came. Exit status
    0 after SIGINT/SIGTERM (one or several, at any moment), 2 with one line on stderr when a value
    given at start-up is refused."""
    rclpy.init(args=argv if argv is not None else sys.argv,
               signal_handler_options=SignalHandlerOptions.NO)
    node = executor = None
    try:
        if not stop:
            node = ClothSimNode()
            executor = SingleThreadedExecutor()
            executor.add_node(node)
        while not stop and rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except StartupError as e:
        print(f"cloth_sim_node: error: {e}", file=sys.stderr)
        return 2
    finally:
        if executor is not None:
            executor.shutdown(timeout_sec=1.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


def main(argv=None) -> int:
    """Entry point of ``cloth_sim_node``; see :func:`cloth_sim.ros.main`."""
    from . import main as ros_main

    return ros_main(argv)


if __name__ == "__main__":
    sys.exit(main())
