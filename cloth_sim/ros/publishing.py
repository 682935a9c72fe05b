"""What a tick publishes (``/clock``, ``~/points``, ``~/mesh``, ``~/colliders``, wrenches, TF,
``~/stats``) and ``/diagnostics``; the messages themselves are built by the pure functions of
:mod:`cloth_sim.ros.messages`.
"""

from __future__ import annotations

import math
import time

from builtin_interfaces.msg import Time as TimeMsg
from diagnostic_msgs.msg import DiagnosticArray
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import PointCloud2
from visualization_msgs.msg import Marker, MarkerArray

from ..tick_stats import TickStats, stability_margin
from . import interface, messages
from .camera_publisher import CameraPublisher
from .frames import Frames
from .link_wrenches import LinkWrenches

STATUS_PERIOD = 5.0  # s of wall time between status log lines
WARN_MARGIN = 0.8  # WARN when dt is above this fraction of stable_dt
#: WARN when the real-time factor over the last RTF_WINDOW seconds is below this: "below 1", less
#: the few per cent that timer jitter and whole-step quantisation give a node that keeps up
RTF_WARN = 0.95
RTF_WINDOW = 2.0


def _stats_type():
    from cloth_sim.msg import Stats  # generated from msg/Stats.msg by rosidl

    return Stats


class Publishing:
    """What the node publishes about its :class:`~cloth_sim.ros.session.Session`: the tick's topics
    (:meth:`publish`), ``/diagnostics`` (:meth:`publish_diagnostics`), TF (:attr:`frames`) and the
    depth camera (:attr:`camera`); the grippers' wrenches through ``manipulation``'s topics, the
    robots' links' through :attr:`link_wrenches`."""

    def __init__(self, node, session, manipulation):
        self.node, self.session, self.manipulation = node, session, manipulation
        self.Stats = _stats_type()
        self.points_pub = interface.publisher(node, "points", PointCloud2)
        self.mesh_pub = interface.publisher(node, "mesh", Marker)
        self.mesh_bytes = messages.MeshBytes()  # (its buffer kept from tick to tick)
        self.stats_pub = interface.publisher(node, "stats", self.Stats)
        self._solver_seen = (0, 0)  # the solver's steps and unconverged steps at the last report
        self.diag_pub = interface.publisher(node, "diagnostics", DiagnosticArray)
        self.colliders_pub = interface.publisher(node, "colliders", MarkerArray)
        self.clock_pub = None  # /clock, made when publish_clock is first on
        self._last_status = time.monotonic()
        self.frames = Frames(node)  # TF
        self.frames.publish_static(session.cfg["world_frame_id"], session.cfg["frame_id"])
        self.camera = CameraPublisher(node, session, self.stamp)  # the depth camera's topics
        self.link_wrenches = LinkWrenches(node, session)  # the robots' links' wrenches

    def configure(self, cfg: dict) -> None:
        """The frames and the camera for the values ``cfg`` (accepted, now the session's)."""
        self.frames.publish_static(cfg["world_frame_id"], cfg["frame_id"])
        self.camera.configure(cfg)

    def stamp(self):
        """The messages' stamp: the simulated time with ``publish_clock``, else the node's
        clock."""
        if self.session.cfg["publish_clock"]:
            t = self.session.sim.time
            sec = math.floor(t)
            return TimeMsg(sec=int(sec), nanosec=min(int(round((t - sec) * 1e9)), 999_999_999))
        return self.node.get_clock().now().to_msg()

    def publish(
        self, t0: float, steps: int, step_wall: float, step_max: float, energy: dict | None = None
    ) -> None:
        """Everything a tick (or ``~/step``) publishes: /clock, the cloud, mesh, markers, wrenches,
        stats; ``energy``: :meth:`Simulator.energy` at the current state, where the caller has it
        (each term costs ~0.2 ms at 128×128)."""
        sim = self.session.sim
        t1 = time.perf_counter()
        stamp = self.stamp()
        frame = self.session.cfg["frame_id"]
        if self.session.cfg["publish_clock"]:
            if self.clock_pub is None:
                self.clock_pub = interface.publisher(self.node, "clock", Clock)
            self.clock_pub.publish(Clock(clock=stamp))
        if self.points_pub.get_subscription_count() > 0:
            self.points_pub.publish(self.point_cloud(stamp))
        if self.mesh_pub.get_subscription_count() > 0:
            self.mesh_pub.publish(
                self.mesh_bytes(sim.positions, sim.model.triangles, frame, stamp)
            )
        if (
            sim.colliders or self.manipulation.grippers
        ) and self.colliders_pub.get_subscription_count() > 0:
            grippers = {name: sim.gripper_pose(name)[0] for name in self.manipulation.grippers}
            self.colliders_pub.publish(
                messages.collider_markers(sim.colliders, frame, stamp, grippers)
            )
        for name, (_, pub) in self.manipulation.grippers.items():
            force, torque = sim.gripper_wrench(name)
            pub.publish(messages.wrench(force, torque, frame, stamp))
        self.link_wrenches.publish(frame, stamp)
        self.frames.publish(sim, frame, stamp, self.camera)
        wall_now = time.monotonic()
        self.session.history.append((wall_now, sim.time))
        while self.session.history and wall_now - self.session.history[0][0] > RTF_WINDOW:
            self.session.history.popleft()
        tick = TickStats.of(
            sim,
            steps=steps,
            energy=energy,
            step_time_mean=step_wall / steps if steps else 0.0,
            step_time_max=step_max,
            tick_wall_time=time.perf_counter() - t0,
            real_time_factor=self.real_time_factor(),
            overruns=self.session.overruns,
            stability_margin=stability_margin(sim.dt, self.session.stable_dt),
            paused=self.session.paused,
        )
        self.stats_pub.publish(messages.stats(self.Stats, stamp, frame, tick))
        self.session.tick_costs.append((steps, step_wall, time.perf_counter() - t1))
        if wall_now - self._last_status >= STATUS_PERIOD:
            self._last_status = wall_now
            self.node.get_logger().info(self.status_line())

    def point_cloud(self, stamp) -> PointCloud2:
        rows, cols = self.cloud_shape()
        return messages.point_cloud(
            self.session.sim.positions, rows, cols, self.session.cfg["frame_id"], stamp
        )

    def cloud_shape(self) -> tuple[int, int]:
        """``~/points``' height and width: the grid's rows and columns, or 1 × vertices (a mesh's
        cloud is unorganised)."""
        model = self.session.sim.model
        return (model.rows, model.cols) if model.rows else (1, model.n_particles)

    def cloth_text(self) -> str:
        """``32×32 provot in cotton`` or ``mesh tshirt.obj (1234 vertices, 2300 triangles) provot``
        (the fabric named where a material maps it: a library name, or the scene's own)."""
        model, session = self.session.sim.model, self.session
        fabric = ""
        if model.meta.get("material") is not None:
            name = session.cfg["material"] or session.scene.material_name
            fabric = f" in {name}" if name else " in the scene's fabric"
        if model.rows:
            return f"{model.rows}×{model.cols} {model.model}{fabric}"
        return (
            f"mesh {session.scene.mesh['file'].name} ({model.n_particles} vertices, "
            f"{len(model.triangles)} triangles) {model.model}{fabric}"
        )

    def real_time_factor(self) -> float:
        if len(self.session.history) < 2:
            return 0.0 if self.session.paused else 1.0
        (w0, s0), (w1, s1) = self.session.history[0], self.session.history[-1]
        return (s1 - s0) / (w1 - w0) if w1 > w0 else 0.0

    def status_line(self) -> str:
        state = "PAUSED " if self.session.paused else ""
        return (
            f"{state}t={self.session.sim.time:.2f} s  {self.session.sim.integrator}  "
            f"dt={self.session.sim.dt:g} s  "
            f"rtf={self.real_time_factor():.2f}  max_strain={self.session.sim.max_strain():+.4f}  "
            f"overruns={self.session.overruns}"
        )

    def diagnostic_status(self):
        sim = self.session.sim
        rtf = self.real_time_factor()
        values = {
            "integrator": sim.integrator,
            "dt": f"{sim.dt:g}",
            "stable_dt": f"{self.session.stable_dt:.6g}",
            "real_time_factor": f"{rtf:.3f}",
            "sim_time": f"{sim.time:.4f}",
            "particles": sim.model.n_particles,
            "max_strain": f"{sim.max_strain():.5f}",
            "overruns": self.session.overruns,
            "paused": str(self.session.paused).lower(),
            "publish_rate": f"{self.session.cfg['publish_rate']:g}",
            "scene": self.session.scene.name,
            "dropped_sim_time": f"{self.session.dropped:.4f}",
            "target_real_time_factor": f"{self.session.cfg['real_time_factor']:g}",
            "grippers": ", ".join(self.manipulation.grippers) or "none",
            "energy_excess": f"{self.session.balance.excess:.4g}",
        }
        return messages.diagnostic_status(
            error=self.session.error,
            paused=self.session.paused,
            rtf=rtf,
            rtf_known=len(self.session.history) >= 2,
            rtf_warn=RTF_WARN * self.session.cfg["real_time_factor"],
            dt=sim.dt,
            stable_dt=self.session.stable_dt,
            warn_margin=WARN_MARGIN,
            values=values,
            energy=self.session.balance.message() if self.session.balance.unstable else None,
            others=[
                p
                for p in (self.solver_problem(), *(s() for s in self.session.problem_sources))
                if p
            ],
        )

    def solver_problem(self) -> str | None:
        """What ``/diagnostics`` says while an iterative method's steps end above its tolerance
        (``vbd``): how many of the steps since the last report did, and the last residual;
        ``None`` while they converge (and for the direct methods)."""
        stats = self.session.sim.integrator_stats
        if "unconverged_steps" not in stats:
            self._solver_seen = (0, 0)
            return None
        seen = (stats["steps"], stats["unconverged_steps"])
        last_steps, last_unconverged = self._solver_seen
        self._solver_seen = seen
        if seen[0] < last_steps:  # the method was selected again: its counters restarted
            last_steps = last_unconverged = 0
        steps, unconverged = seen[0] - last_steps, seen[1] - last_unconverged
        if unconverged == 0:
            return None
        return (
            f"{unconverged} of the last {steps} {self.session.sim.integrator} steps ended "
            f"unconverged (residual {stats['last_residual']:.3g} > tolerance "
            f"{stats['tolerance']:.3g}: raise its iterations or lower dt)"
        )

    def publish_diagnostics(self) -> None:
        self.diag_pub.publish(
            messages.diagnostic_array(
                self.diagnostic_status(), self.node.get_clock().now().to_msg()
            )
        )
