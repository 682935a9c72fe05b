"""``cloth_sim_node``: the simulator on the ROS graph — a thin adapter over :mod:`cloth_sim`.

The node composes its parts, each an object built with what it needs, over one
:class:`~cloth_sim.ros.session.Session` (the running :class:`~cloth_sim.simulator.Simulator` and
what the parts share about it):

* :mod:`~cloth_sim.ros.gate` — the parameters: the start-up values checked whole, then the session
  built; every change through rclpy's pre-set, on-set and post-set callbacks;
* :mod:`~cloth_sim.ros.ticker` — the timer: each tick's steps within its budget, the backlog, the
  poses reached over a tick;
* :mod:`~cloth_sim.ros.control` — pause, reset, stepping on request, checkpoints and recovery after
  a blow-up;
* :mod:`~cloth_sim.ros.manipulation` — grippers and the colliders' pose topics;
* :mod:`~cloth_sim.ros.publishing` — what a tick publishes, ``/diagnostics``, TF
  (:mod:`~cloth_sim.ros.frames`) and the depth camera (:mod:`~cloth_sim.ros.camera_publisher`); the
  messages are built by the pure functions of :mod:`~cloth_sim.ros.messages`;
* :mod:`~cloth_sim.ros.sim_interfaces` — the ROS simulation standard's services and action;
* :mod:`~cloth_sim.ros.robot_state` — a robot from ``robot_description``, moved by
  ``/joint_states``.

The process (:func:`cloth_sim.ros.main`, then :func:`run`) handles SIGINT/SIGTERM itself (rclpy's
handlers are off): a signal at any moment, or two (``ros2 launch`` forwards Ctrl-C), only asks the
spin loop to stop; the node is then destroyed and the process exits 0.
"""

from __future__ import annotations

import gc
import sys

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from ..kernels import compile_kernels
from .control import SimulationControl
from .gate import ParameterGate, StartupError, as_declared, settle_garbage
from .manipulation import Manipulation
from .publishing import Publishing
from .robot_state import RobotState
from .sim_interfaces import SimulationInterfaces
from .ticker import Stepper, Ticker


class ClothSimNode(Node):
    """The ``cloth_sim`` node. ``parameter_overrides`` etc. are passed to
    :class:`rclpy.node.Node`."""

    def __init__(self, **kwargs):
        super().__init__("cloth_sim", **kwargs)
        # an integer for a double (``-p dt:=1``): the schema takes it, rclpy's declaration would
        # not
        self._parameter_overrides = {
            n: as_declared(p) for n, p in self._parameter_overrides.items()
        }
        overrides = {name: p.value for name, p in self._parameter_overrides.items()}
        self.gate = ParameterGate(self, overrides)  # the values checked whole, then built
        session = self.session = self.gate.session
        # every kernel compiled (or loaded from numba's cache) now, not in the tick that first
        # needs it: switching to kang live once stalled the node for 6 s
        kernels = compile_kernels()
        self.manipulation = Manipulation(self, session)
        self.publishing = Publishing(self, session, self.manipulation)
        self.robot_state = RobotState(self, session)
        self.stepper = Stepper(session, self.manipulation, self.robot_state)
        self.control = SimulationControl(
            self, session, self.stepper, self.publishing, self.manipulation
        )
        self.interfaces = SimulationInterfaces(
            self, session, self.control, self.manipulation, self.publishing.stamp
        )
        session.restart_listeners.append(self.interfaces.restarted)
        session.restart_listeners.append(self.robot_state.restarted)
        session.problem_sources.append(self.robot_state.problem)
        self.robot_state.configure(session.cfg)
        self.ticker = Ticker(
            self, session, self.stepper, self.control, self.publishing, self.interfaces
        )
        self.gate.open(self.manipulation, self.publishing, self.ticker, self.robot_state)
        self.diag_timer = self.create_timer(1.0, self.publishing.publish_diagnostics)
        settle_garbage()
        self.get_logger().info(
            f"scene {session.scene.name}: {self.publishing.cloth_text()}, "
            f"{session.sim.integrator} on the {session.sim.device}, dt={session.sim.dt:g} s, "
            f"{session.cfg['publish_rate']:g} "
            f"Hz, terms: {', '.join(session.sim.active_terms)}; kernels ready in {kernels:.2f} s"
        )

    def destroy_node(self):
        """Destroy the node with everything it created. rclpy's own leaves the action server,
        which keeps the node (and its context's DDS participant) alive in the graph with the
        action's topics until the process ends: a later node of this name on the same domain met
        it there."""
        self.interfaces.destroy()
        super().destroy_node()

    # the session's main pieces, for a program that embeds the node (tests, the fuzz)
    @property
    def sim(self):
        return self.session.sim

    @property
    def cfg(self) -> dict:
        return self.session.cfg

    @property
    def scene(self):
        return self.session.scene

    @property
    def paused(self) -> bool:
        return self.session.paused

    @property
    def error(self) -> str | None:
        return self.session.error


# ---------------------------------------------------------------------- process
def run(argv, stop) -> int:
    """Spin the node until ``stop`` (a :class:`cloth_sim.ros.StopRequest`, installed by
    :func:`cloth_sim.ros.main` before anything heavy is imported) says a signal came. Exit status
    0 after SIGINT/SIGTERM (one or several, at any moment), 2 with one line on stderr when a value
    given at start-up is refused."""
    rclpy.init(
        args=argv if argv is not None else sys.argv, signal_handler_options=SignalHandlerOptions.NO
    )
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
        # (settle_garbage), and a cholespy solver still alive when nanobind shuts down is
        # reported as a leak on stderr
        node = executor = None
        gc.unfreeze()
        gc.collect()
    return 0
