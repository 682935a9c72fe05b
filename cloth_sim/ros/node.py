"""``cloth_sim_node``: the simulator on the ROS graph — a thin adapter over :mod:`cloth_sim`.

Every tick (``publish_rate`` Hz) advances the simulation by ``1/publish_rate`` s in whole steps of
``dt`` (the remainder carries over), then publishes. This module wires the node's parts, each its own
module over the one :class:`~cloth_sim.simulator.Simulator` (``self.sim``):

* :mod:`~cloth_sim.ros.gate` — the parameter gate (pre-set, on-set, post-set as rclpy intends) and
  the building of the model and simulator;
* the tick clock here (:meth:`ClothSimNode._tick`, :meth:`ClothSimNode._advance`: budgets, backlog,
  poses reached over a tick) and :mod:`~cloth_sim.ros.control` — pause, reset, stepping on request,
  checkpoints and recovery after a blow-up;
* :mod:`~cloth_sim.ros.manipulation` — grippers and the colliders' pose topics;
* :mod:`~cloth_sim.ros.publishing` — what a tick publishes, and ``/diagnostics``; the messages are
  built by the pure functions of :mod:`~cloth_sim.ros.messages`; TF by :mod:`~cloth_sim.ros.frames`;
* :mod:`~cloth_sim.ros.sim_interfaces` — the ROS simulation standard's services and action.

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
from rclpy.exceptions import ParameterException
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import PointCloud2
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import Marker, MarkerArray

from .. import settings
from ..parameters import SCHEMA
from ..scene import SceneError, load_scene
from ..energy_balance import EnergyBalance
from ..simulator import SimulationDiverged, compile_kernels
from . import params as P
from .camera_publisher import CameraPublisher
from .control import CHECKPOINTS, SimulationControl
from .frames import Frames
from .gate import MODEL_KEYS, ParameterGate, _as_declared, _settle_garbage  # noqa: F401 (MODEL_KEYS: fuzz_node)
from .manipulation import Manipulation
from .publishing import Publishing
from .sim_interfaces import SimulationInterfaces

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


class StartupError(ValueError):
    """A value the node cannot start with; one line naming it."""


def _stats_type():
    from cloth_sim.msg import Stats  # generated from msg/Stats.msg by rosidl

    return Stats


def _srv_types():
    from cloth_sim.srv import Grasp, Release, Step  # generated from srv/ by rosidl

    return Grasp, Release, Step


class ClothSimNode(ParameterGate, SimulationControl, Manipulation, Publishing, Node):
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
        # the combination checks a parameter change passes (thickness, camera, stable step)
        reason, _, self._stable_dt = settings.refusal(self.cfg, model)
        if reason:
            raise StartupError(reason)
        self.sim = self._build_simulator(self.cfg, model, self.scene)
        self._fit_solver(self.cfg)
        self.balance = EnergyBalance(self.sim)  # energy no source put in: WARN on /diagnostics
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
        self.camera_pub = CameraPublisher(self)  # the depth camera's topics
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
                self.balance.sample()
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
            if self._twists:  # colliders and grippers moving at a set velocity
                self._apply_twists(sim.dt)
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













    # ------------------------------------------------------------------ colliders














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
        # the node and what it holds (solvers' factorisations among them) freed now, not left to
        # the interpreter's exit: the start-up froze them out of the collector's reach
        # (_settle_garbage), and a cholespy solver still alive when nanobind shuts down is
        # reported as a leak on stderr
        node = executor = None
        gc.unfreeze()
        gc.collect()
    return 0


def main(argv=None) -> int:
    """Entry point of ``cloth_sim_node``; see :func:`cloth_sim.ros.main`."""
    from . import main as ros_main

    return ros_main(argv)


if __name__ == "__main__":
    sys.exit(main())
