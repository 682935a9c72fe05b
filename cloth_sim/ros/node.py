"""``cloth_sim_node``: the simulator on the ROS graph — a thin adapter over :mod:`cloth_sim`.

Every tick (``publish_rate`` Hz) advances the simulation by ``1/publish_rate`` s in whole steps of
``dt`` (the remainder carries over), then publishes ``~/points`` (organised PointCloud2),
``~/mesh`` (Marker, only with subscribers) and ``~/stats``; ``/diagnostics`` at 1 Hz. Parameters
apply live (see :mod:`cloth_sim.ros.params`); a blow-up restores the last good state and pauses.
"""

from __future__ import annotations

import array
import collections
import math
import sys
import time

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point
from rcl_interfaces.msg import SetParametersResult
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import ColorRGBA
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import Marker

from .. import integrators
from ..model import GRID_FAMILIES
from ..scene import load_scene
from ..simulator import SimulationDiverged, Simulator
from . import params as P

STATUS_PERIOD = 5.0  # s of wall time between status log lines
WARN_MARGIN = 0.8    # WARN when dt is above this fraction of stable_dt
#: WARN when the real-time factor over the last RTF_WINDOW seconds is below this: "below 1", less
#: the few per cent that timer jitter and whole-step quantisation give a node that keeps up
RTF_WARN = 0.95
RTF_WINDOW = 2.0

_FIELDS = [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1)
           for i, n in enumerate("xyz")]


def _stats_type():
    from cloth_sim.msg import Stats  # generated from msg/Stats.msg by rosidl

    return Stats


class ClothSimNode(Node):
    """The ``cloth_sim`` node. ``parameter_overrides`` etc. are passed to :class:`rclpy.node.Node`."""

    def __init__(self, **kwargs):
        super().__init__("cloth_sim", **kwargs)
        self.Stats = _stats_type()
        # the scene first: it provides the other parameters' defaults
        self.declare_parameter("scene", "hanging", P.SPEC["scene"].descriptor())
        scene_name = self.get_parameter("scene").value
        reason = P.check_value("scene", scene_name)
        if reason:
            raise ValueError(reason)
        self.scene = load_scene(scene_name)
        for name, value in P.defaults(self.scene).items():
            if name != "scene":
                self.declare_parameter(name, value, P.SPEC[name].descriptor())
        self.cfg = {name: self.get_parameter(name).value for name in P.SPEC}
        for name, value in self.cfg.items():
            reason = P.check_value(name, value)
            if reason:
                raise ValueError(reason)
        self.sim = self._build_simulator(self.cfg, self.scene)
        reason, self._stable_dt = self._check_stability(self.cfg)
        if reason:
            raise ValueError(reason)

        self.paused = False
        self.error: str | None = None
        self.overruns = 0
        self._carry = 0.0
        self._history = collections.deque()  # (wall, sim time) over the last RTF_WINDOW s
        self._tick_costs = collections.deque(maxlen=120)  # (steps, step wall, publish wall)
        self._last_status = time.monotonic()
        self._pending_scene = None

        self.points_pub = self.create_publisher(PointCloud2, "~/points", 10)
        self.mesh_pub = self.create_publisher(Marker, "~/mesh", 10)
        self.stats_pub = self.create_publisher(self.Stats, "~/stats", 10)
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.create_service(SetBool, "~/pause", self._on_pause)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.timer = self.create_timer(1.0 / self.cfg["publish_rate"], self._tick)
        self.diag_timer = self.create_timer(1.0, self._publish_diagnostics)
        self.get_logger().info(
            f"scene {self.scene.name}: {self.cfg['rows']}×{self.cfg['cols']} {self.cfg['model']}, "
            f"{self.sim.integrator}, dt={self.sim.dt:g} s, {self.cfg['publish_rate']:g} Hz, "
            f"terms: {', '.join(self.sim.active_terms)}")

    # ------------------------------------------------------------------ building
    def _build_simulator(self, cfg: dict, scene) -> Simulator:
        model = scene.build_model(rows=cfg["rows"], cols=cfg["cols"], spacing=cfg["spacing"],
                                  particle_mass=cfg["particle_mass"], model=cfg["model"],
                                  stiffness={f: cfg[f"stiffness.{f}"] for f in GRID_FAMILIES},
                                  damping={f: cfg[f"damping.{f}"] for f in GRID_FAMILIES})
        return Simulator(model, integrator=cfg["integrator"], dt=cfg["dt"], gravity=cfg["gravity"],
                         wind=self._wind(cfg), drag=cfg["drag"],
                         strain_limit=cfg["strain_limit"] or None)

    @staticmethod
    def _wind(cfg):
        w = cfg["wind.strength"] * np.asarray(cfg["wind.direction"], dtype=float)
        return w if np.any(w) else None

    def stable_dt(self) -> float:
        """The current explicit method's stable_dt (cached); ``inf`` for implicit methods."""
        if self._stable_dt is None:
            implicit = integrators.get(self.sim.integrator).implicit
            self._stable_dt = math.inf if implicit else self.sim.stable_dt()
        return self._stable_dt

    def _check_stability(self, cfg: dict, sim: Simulator | None = None):
        """``(reason, stable_dt)``: the reason to refuse a dt above the explicit method's stable_dt
        (``None`` if it is fine or ``allow_unstable``), and that limit when it was computed (``None``
        otherwise), so the node need not compute it again once the change is applied."""
        if integrators.get(cfg["integrator"]).implicit:
            return None, math.inf
        if cfg["allow_unstable"]:
            return None, None
        sim = sim or self.sim
        probe = Simulator(sim.model, integrator=cfg["integrator"], dt=cfg["dt"], gravity=cfg["gravity"])
        for f in GRID_FAMILIES:
            probe.set_stiffness(f, cfg[f"stiffness.{f}"])
            probe.set_damping(f, cfg[f"damping.{f}"])
        limit = probe.stable_dt()
        if cfg["dt"] > limit:
            return (f"dt={cfg['dt']:g} s is above the stable limit of {cfg['integrator']} for this "
                    f"cloth, stable_dt={limit:.4g} s: choose dt <= {limit:.4g}, an implicit "
                    f"integrator, or set allow_unstable to true"), limit
        return None, limit

    # ------------------------------------------------------------------ parameters
    def _on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        """Validate the whole batch, then apply it; a refused batch changes nothing."""
        changes = {p.name: p.value for p in parameters if p.name in P.SPEC}
        for name, value in changes.items():
            reason = P.check_value(name, value)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        cand = dict(self.cfg)
        cand.update({k: (list(v) if P.SPEC[k].type == P.DA else v) for k, v in changes.items()})
        scene = self.scene
        if "scene" in changes and changes["scene"] != self.cfg["scene"]:
            scene = load_scene(changes["scene"])
            for k, v in P.scene_values(scene).items():  # the new scene brings its own values
                if k not in changes:
                    cand[k] = v
        topology = any(cand[k] != self.cfg[k] for k in P.TOPOLOGY) or scene is not self.scene
        if "publish_rate" in changes:
            reason = self._check_rate(cand)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        try:
            new_sim = self._build_simulator(cand, scene) if topology else None
            reason, limit = self._check_stability(cand, new_sim)
        except ValueError as e:  # e.g. a scene whose pins fall outside the new grid size
            return SetParametersResult(successful=False, reason=str(e))
        if reason:
            return SetParametersResult(successful=False, reason=reason)
        # accepted: apply everything (nothing below can fail on validated values)
        if topology:
            self.sim = new_sim
            self.scene = scene
            self._carry = 0.0
            self._history.clear()
            if "scene" in changes and changes["scene"] != self.cfg["scene"]:
                self._pending_scene = {k: cand[k] for k in P.scene_values(scene) if k not in changes}
        else:
            self._apply_live(cand)
        rate_changed = cand["publish_rate"] != self.cfg["publish_rate"]
        self.cfg = cand
        self._stable_dt = limit  # None when not computed: stable_dt() computes it when asked
        if rate_changed:
            self.timer.cancel()
            self.destroy_timer(self.timer)
            self.timer = self.create_timer(1.0 / cand["publish_rate"], self._tick)
        if self._pending_scene:  # report the scene's values through the parameters, after this call
            self._scene_timer = self.create_timer(0.0, self._publish_scene_values)
        return SetParametersResult(successful=True)

    def _publish_scene_values(self):
        self._scene_timer.cancel()
        self.destroy_timer(self._scene_timer)
        values, self._pending_scene = self._pending_scene, None
        self.set_parameters([Parameter(k, value=v) for k, v in values.items()])

    def _apply_live(self, cand: dict) -> None:
        sim, cur = self.sim, self.cfg
        for f in GRID_FAMILIES:
            if cand[f"stiffness.{f}"] != cur[f"stiffness.{f}"]:
                sim.set_stiffness(f, cand[f"stiffness.{f}"])
            if cand[f"damping.{f}"] != cur[f"damping.{f}"]:
                sim.set_damping(f, cand[f"damping.{f}"])
        if cand["integrator"] != sim.integrator:
            sim.set_integrator(cand["integrator"])
        if cand["dt"] != sim.dt:
            sim.dt = cand["dt"]
        if list(cand["gravity"]) != list(cur["gravity"]):
            sim.gravity = cand["gravity"]
        if (cand["wind.strength"], list(cand["wind.direction"])) != (cur["wind.strength"],
                                                                    list(cur["wind.direction"])):
            sim.wind = self._wind(cand)
        if cand["drag"] != cur["drag"]:
            sim.drag = cand["drag"]
        if cand["strain_limit"] != cur["strain_limit"]:
            sim.strain_limit = cand["strain_limit"] or None

    def _check_rate(self, cand: dict) -> str | None:
        """A rate is refused when the measured cost of stepping and publishing would not fit."""
        if len(self._tick_costs) < 10:
            return None
        steps = sum(c[0] for c in self._tick_costs)
        step_wall = sum(c[1] for c in self._tick_costs)
        pub_wall = sum(c[2] for c in self._tick_costs) / len(self._tick_costs)
        per_step = step_wall / steps if steps else 0.0
        load = per_step / cand["dt"] + cand["publish_rate"] * pub_wall
        if load > 1.0:
            return (f"publish_rate={cand['publish_rate']:g} Hz cannot be met: stepping "
                    f"({1e3 * per_step:.3f} ms/step at dt={cand['dt']:g}) and publishing "
                    f"({1e3 * pub_wall:.3f} ms/tick) would need {load:.2f} s of work per second; "
                    f"lower publish_rate, or raise dt")
        return None

    # ------------------------------------------------------------------ services
    def _on_reset(self, request, response):
        self.sim.reset()
        self._carry = 0.0
        self._history.clear()
        self.error = None
        self.paused = False
        response.success = True
        response.message = f"reset {self.scene.name} to its initial shape at rest, time 0"
        return response

    def _on_pause(self, request, response):
        if not request.data and self.error:
            self.error = None  # the user un-pauses after a blow-up: try again from the good state
        self.paused = bool(request.data)
        self._history.clear()
        response.success = True
        response.message = "paused" if self.paused else "running"
        return response

    # ------------------------------------------------------------------ tick
    def _tick(self) -> None:
        t0 = time.perf_counter()
        period = 1.0 / self.cfg["publish_rate"]
        sim = self.sim
        steps, step_max, step_wall = 0, 0.0, 0.0
        if not self.paused:
            self._carry += period
            n = int(math.floor(self._carry / sim.dt + 1e-9))
            self._carry -= n * sim.dt
            try:
                for _ in range(n):
                    s0 = time.perf_counter()
                    sim.step()
                    el = time.perf_counter() - s0
                    step_wall += el
                    step_max = max(step_max, el)
                    steps += 1
            except SimulationDiverged as e:
                self.error = str(e)
                self.paused = True
                self._carry = 0.0
                self.get_logger().error(f"{e} Paused: fix the parameters, then call ~/pause "
                                        f"with data=false or ~/reset.")
                self._publish_diagnostics()
        t1 = time.perf_counter()
        stamp = self.get_clock().now().to_msg()
        if self.points_pub.get_subscription_count() > 0:
            self.points_pub.publish(self.point_cloud(stamp))
        if self.mesh_pub.get_subscription_count() > 0:
            self.mesh_pub.publish(self.mesh(stamp))
        wall_now = time.monotonic()
        self._history.append((wall_now, sim.time))
        while self._history and wall_now - self._history[0][0] > RTF_WINDOW:
            self._history.popleft()
        self.stats_pub.publish(self._stats(stamp, steps, step_wall, step_max, t0))
        tick_wall = time.perf_counter() - t0
        if tick_wall > period:
            self.overruns += 1
        self._tick_costs.append((steps, step_wall, time.perf_counter() - t1))
        if wall_now - self._last_status >= STATUS_PERIOD:
            self._last_status = wall_now
            self.get_logger().info(self.status_line())

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

    # ------------------------------------------------------------------ messages
    def point_cloud(self, stamp) -> PointCloud2:
        rows, cols = self.cfg["rows"], self.cfg["cols"]
        msg = PointCloud2()
        msg.header.stamp = stamp
        msg.header.frame_id = self.cfg["frame_id"]
        msg.height, msg.width = rows, cols
        msg.fields = _FIELDS
        msg.is_bigendian = sys.byteorder == "big"
        msg.point_step = 12
        msg.row_step = 12 * cols
        msg.is_dense = True  # the guard never lets a non-finite state through
        msg.data = array.array("B", self.sim.positions.astype(np.float32).tobytes())
        return msg

    def mesh(self, stamp) -> Marker:
        m = Marker()
        m.header.stamp = stamp
        m.header.frame_id = self.cfg["frame_id"]
        m.ns, m.id = "cloth", 0
        m.type, m.action = Marker.TRIANGLE_LIST, Marker.ADD
        m.pose.orientation.w = 1.0
        m.scale.x = m.scale.y = m.scale.z = 1.0
        m.color = ColorRGBA(r=0.2, g=0.5, b=0.9, a=1.0)
        verts = self.sim.positions[self.sim.model.triangles.ravel()].tolist()
        m.points = [Point(x=p[0], y=p[1], z=p[2]) for p in verts]
        return m

    def _stats(self, stamp, steps, step_wall, step_max, t0):
        sim = self.sim
        e = sim.energy()
        msg = self.Stats()
        msg.header.stamp = stamp
        msg.header.frame_id = self.cfg["frame_id"]
        msg.integrator = sim.integrator
        msg.dt = sim.dt
        msg.steps = steps
        msg.step_time_mean = step_wall / steps if steps else 0.0
        msg.step_time_max = step_max
        msg.tick_wall_time = time.perf_counter() - t0
        msg.real_time_factor = self.real_time_factor()
        msg.sim_time = sim.time
        msg.kinetic_energy = e["kinetic"]
        msg.potential_energy = e["spring"] + e["gravity"]
        msg.max_strain = sim.max_strain()
        msg.overruns = self.overruns
        limit = self.stable_dt()
        msg.stability_margin = sim.dt / limit if math.isfinite(limit) and limit > 0 else (
            0.0 if math.isinf(limit) else math.inf)
        msg.paused = self.paused
        return msg

    def diagnostic_status(self) -> DiagnosticStatus:
        sim = self.sim
        rtf = self.real_time_factor()
        limit = self.stable_dt()
        level, message = DiagnosticStatus.OK, "running"
        problems = []
        if self.error:
            level, message = DiagnosticStatus.ERROR, f"simulation diverged and is paused: {self.error}"
        else:
            if not self.paused and len(self._history) >= 2 and rtf < RTF_WARN:
                problems.append(f"real-time factor {rtf:.2f} < 1")
            if math.isfinite(limit) and sim.dt > WARN_MARGIN * limit:
                problems.append(f"dt={sim.dt:g} s is above {WARN_MARGIN:.0%} of stable_dt={limit:.4g} s")
            if problems:
                level, message = DiagnosticStatus.WARN, "; ".join(problems)
            elif self.paused:
                message = "paused"
        values = {
            "integrator": sim.integrator, "dt": f"{sim.dt:g}", "stable_dt": f"{limit:.6g}",
            "real_time_factor": f"{rtf:.3f}", "sim_time": f"{sim.time:.4f}",
            "particles": str(sim.model.n_particles), "max_strain": f"{sim.max_strain():.5f}",
            "overruns": str(self.overruns), "paused": str(self.paused).lower(),
            "publish_rate": f"{self.cfg['publish_rate']:g}", "scene": self.scene.name,
        }
        return DiagnosticStatus(level=level, name="cloth_sim: simulation", message=message,
                                hardware_id="cloth_sim",
                                values=[KeyValue(key=k, value=v) for k, v in values.items()])

    def _publish_diagnostics(self) -> None:
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.status = [self.diagnostic_status()]
        self.diag_pub.publish(msg)


def main(argv=None) -> int:
    """Entry point of ``cloth_sim_node`` (``ros2 run cloth_sim cloth_sim_node``)."""
    rclpy.init(args=argv if argv is not None else sys.argv)
    node = None
    try:
        node = ClothSimNode()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ValueError as e:  # a refused parameter or scene at start-up
        print(f"cloth_sim_node: error: {e}", file=sys.stderr)
        return 2
    finally:
        if node is not None:
            node.destroy_node()
        if rclpy.ok():
            rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
