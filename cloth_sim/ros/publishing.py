"""What a tick publishes (``/clock``, ``~/points``, ``~/mesh``, ``~/colliders``, wrenches, TF,
``~/stats``) and ``/diagnostics``; the messages themselves are built by the pure functions of
:mod:`cloth_sim.ros.messages`.
"""

from __future__ import annotations

import math
import time

from builtin_interfaces.msg import Time as TimeMsg
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import PointCloud2

from . import messages

STATUS_PERIOD = 5.0  # s of wall time between status log lines
WARN_MARGIN = 0.8    # WARN when dt is above this fraction of stable_dt
#: WARN when the real-time factor over the last RTF_WINDOW seconds is below this: "below 1", less
#: the few per cent that timer jitter and whole-step quantisation give a node that keeps up
RTF_WARN = 0.95
RTF_WINDOW = 2.0


class Publishing:
    """Publishing and diagnostics (a mixin of :class:`~cloth_sim.ros.node.ClothSimNode`)."""

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
        self.frames.publish(sim, frame, stamp, self.camera_pub)
        wall_now = time.monotonic()
        self._history.append((wall_now, sim.time))
        while self._history and wall_now - self._history[0][0] > RTF_WINDOW:
            self._history.popleft()
        self.stats_pub.publish(messages.stats(
            self.Stats, stamp=stamp, frame_id=frame, integrator=sim.integrator, dt=sim.dt,
            steps=steps, step_wall=step_wall, step_max=step_max,
            tick_wall=time.perf_counter() - t0, rtf=self.real_time_factor(), sim_time=sim.time,
            energy=sim.energy(), max_strain=sim.max_strain(), overruns=self.overruns,
            stable_dt=self._stable_dt, paused=self.paused, solver=sim.integrator_stats))
        self._tick_costs.append((steps, step_wall, time.perf_counter() - t1))
        if wall_now - self._last_status >= STATUS_PERIOD:
            self._last_status = wall_now
            self.get_logger().info(self.status_line())

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
            "energy_excess": f"{self.balance.excess:.4g}",
        }
        return messages.diagnostic_status(
            error=self.error, paused=self.paused, rtf=rtf, rtf_known=len(self._history) >= 2,
            rtf_warn=RTF_WARN * self.cfg["real_time_factor"], dt=sim.dt, stable_dt=self._stable_dt, warn_margin=WARN_MARGIN,
            values=values, energy=self.balance.message() if self.balance.unstable else None)

    def _publish_diagnostics(self) -> None:
        self.diag_pub.publish(messages.diagnostic_array(self.diagnostic_status(),
                                                        self.get_clock().now().to_msg()))
