"""Seeded fuzzing of a live cloth_sim_node through its parameter services.

    .venv/bin/python test/fuzz_node.py --sets 5000 --seed 1      (what `make fuzz` runs)

A 16×16 node (30 Hz) and a probe run in this process on their own ROS domain. Each set is 1–4
parameters — valid values, NaN, ±inf, zeros, huge values, wrong types, wrong array lengths, unknown
names, dt near the method's limit, scenes good and bad — sent through ``~/set_parameters`` or
``~/set_parameters_atomically``. Every answer is checked against the schema
(:data:`cloth_sim.parameters.SCHEMA`) and against what then runs; the figures printed at the end:
crashes, hangs (a ~/stats interval over 2 ticks beyond the time the node spent in the request's
parameter callbacks and beyond the longest single step or one-step tick — a tick cannot cut a step
short —, outside a rebuild), slow answers (over 0.1 s in those callbacks, outside a rebuild),
invalid values accepted, valid values refused (a refusal by the stability limit counts as right
when an independent simulator agrees that dt is above it), refusals not naming a parameter of the
set, non-finite points published, accepted values that are not what runs, and blow-ups after sets
accepted without ``allow_unstable`` (a blow-up that an independent run at a quarter of the step
repeats, or that run passes half the guard's 1000 m/s, comes from the forces, not the step, e.g. a
400 N wind on 10 g particles: counted apart, as ``dt_independent_runaways``).
"""

from __future__ import annotations

import argparse
import math
import os
import re
import sys
import time
from pathlib import Path

import numpy as np
import rclpy
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters, SetParametersAtomically
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from sensor_msgs.msg import PointCloud2
from std_srvs.srv import SetBool, Trigger

from cloth_sim.materials import get as get_fabric
from cloth_sim.model import GRID_FAMILIES
from cloth_sim.msg import Stats
from cloth_sim.parameters import REBUILD, SCHEMA, ParameterError
from cloth_sim.ros.node import ClothSimNode
from cloth_sim.scene import load_scene
from cloth_sim.settings import MODEL_KEYS
from cloth_sim.simulator import SimulationDiverged, Simulator

RATE = 30.0
#: a ~/stats interval longer than this many periods (beyond the request's own callback time and the
#: longest step in it) is a hang: the issue's "no stats gap over 2 ticks"
HANG_TICKS = 2.0
SCENES = ["hanging", "flag", "free_fall", "curtain", "table", "drape", "fold"]
BAD_SCENES = ["nowhere", "x" * 300, "/etc", "/nonexistent/s.yaml", ""]


def _value_msg(value) -> ParameterValue | None:
    """A ParameterValue for any Python value (``None`` for NOT_SET)."""
    T = ParameterType
    if value is None:
        return ParameterValue(type=T.PARAMETER_NOT_SET)
    if isinstance(value, bool):
        return ParameterValue(type=T.PARAMETER_BOOL, bool_value=value)
    if isinstance(value, int):
        return ParameterValue(type=T.PARAMETER_INTEGER, integer_value=value)
    if isinstance(value, float):
        return ParameterValue(type=T.PARAMETER_DOUBLE, double_value=value)
    if isinstance(value, str):
        return ParameterValue(type=T.PARAMETER_STRING, string_value=value)
    if all(isinstance(v, bool) for v in value):
        return ParameterValue(type=T.PARAMETER_BOOL_ARRAY, bool_array_value=list(value))
    if all(isinstance(v, float) for v in value):
        return ParameterValue(type=T.PARAMETER_DOUBLE_ARRAY, double_array_value=list(value))
    return ParameterValue(
        type=T.PARAMETER_STRING_ARRAY, string_array_value=[str(v) for v in value]
    )


class Generator:
    def __init__(self, rng: np.random.Generator, node: ClothSimNode):
        self.rng, self.node = rng, node

    def pick(self, options):
        return options[int(self.rng.integers(len(options)))]

    def number(self, spec):
        r = self.rng.random()
        if r < 0.55:  # valid
            lo, hi = spec.lo, spec.hi
            if spec.name in ("rows", "cols"):
                return int(self.rng.integers(2, 25))
            if spec.name == "dt":
                limit = self.node.session.stable_dt
                if math.isfinite(limit) and self.rng.random() < 0.5:
                    return float(
                        min(1.0, max(1e-7, limit * self.pick([0.5, 0.9, 0.99, 1.01, 1.1, 3])))
                    )
                return float(10 ** self.rng.uniform(-5, -2.5))
            if spec.name == "spacing":
                return float(10 ** self.rng.uniform(-2, 0))
            if spec.name == "real_time_factor":
                return float(self.pick([0.0, 0.5, 1.0, 2.0, 10.0]))
            if spec.name == "thickness":
                return float(10 ** self.rng.uniform(-4, -1))
            if spec.name == "publish_rate":
                return float(self.pick([10.0, 30.0, 60.0, 100.0]))
            if spec.type is int:
                return int(self.rng.integers(lo, hi + 1))
            if lo > 0 or spec.name.startswith(("stiffness", "damping", "drag", "wind")):
                return float(lo + (hi - lo) * 10 ** self.rng.uniform(-9, 0)) if lo >= 0 else 0.0
            return float(self.rng.uniform(lo, hi))
        return self.pick(
            [
                math.nan,
                math.inf,
                -math.inf,
                0.0,
                -1.0,
                1e300,
                -1e-3,
                spec.hi * 1.5 if spec.hi else 1e9,
                "abc",
                True,
                [1.0, 2.0],
                None,
            ]
        )

    def value(self, name):
        if name not in SCHEMA:  # an unknown name, or use_sim_time: never true here, since with no
            return self.pick([1.0, "x", False, [True]])  # /clock the node's time stands still
        spec = SCHEMA[name]
        r = self.rng.random()
        if spec.type is bool:
            return bool(self.rng.random() < 0.5) if r < 0.8 else self.pick([[True], 1, "yes"])
        if spec.type is str:
            if name == "scene":
                return str(self.pick(SCENES if r < 0.6 else BAD_SCENES))
            if spec.choices:
                return str(self.pick(spec.choices)) if r < 0.8 else self.pick(["rk5", "", 3])
            return "cloth" if r < 0.8 else self.pick(["", 1.5])
        if spec.type == "vector2":  # a grid's size: [w, h], or [0, 0] for none
            if r < 0.6:
                return [float(v) for v in self.rng.uniform(0.2, 2.0, 2)]
            return self.pick([[0.0, 0.0], [1.0, 0.0], [1.0], [1.0, math.inf], -1.0, "big"])
        if spec.type == "vector3":
            if r < 0.6:
                return [float(v) for v in self.rng.uniform(-20, 20, 3)]
            return self.pick(
                [
                    [0.0, 1.0],
                    [0.0, 0.0, math.nan],
                    [1.0, 2.0, 3.0, 4.0],
                    [0.0, 0.0, 1e9],
                    9.81,
                    "down",
                ]
            )
        v = self.number(spec)
        return v.item() if isinstance(v, np.generic) else v

    def params(self):
        names = list(SCHEMA) + ["no_such_parameter", "use_sim_time"]
        weights = np.array([0.3 if n in REBUILD else 1.0 for n in names])
        k = int(self.rng.integers(1, 5))
        chosen = self.rng.choice(names, size=k, replace=False, p=weights / weights.sum())
        return [(str(n), self.value(str(n))) for n in chosen]


def _changed(cfg: dict, start: dict) -> dict:
    """The configuration's values that differ from the node's start-up ones (for the examples)."""
    return {k: v for k, v in cfg.items() if v != start.get(k)}


def schema_valid(name, value) -> bool:
    if name not in SCHEMA:
        return name == "use_sim_time" and isinstance(value, bool)
    if value is None:
        return False
    try:
        SCHEMA[name].check(value)
        return True
    except ParameterError:
        return False


def limit_refusal_is_right(cfg: dict, params) -> bool:
    """Whether dt is above the stable limit of the configuration ``cfg`` updated with ``params``,
    by a simulator built for it from the scene (not the node's own check)."""
    cand = dict(cfg)
    for name, value in params:
        if name in SCHEMA:
            cand[name] = SCHEMA[name].check(value)
    if cand["allow_unstable"]:
        return False
    scene = load_scene(cand["scene"])
    fabric = get_fabric(cand["material"]) if cand["material"] else scene.material
    size = tuple(cand["size"]) if cand["size"][0] > 0 else None
    cloth = (
        {"material": fabric, "size": size}
        if fabric is not None
        else {
            "size": size,
            "particle_mass": cand["particle_mass"],
            # a grid given by its mass per area: the particles' shares follow from density
            "density": cand["density"] if scene.grid_density is not None else None,
            "stiffness": {f: cand[f"stiffness.{f}"] for f in GRID_FAMILIES},
            "damping": {f: cand[f"damping.{f}"] for f in GRID_FAMILIES},
        }
    )
    sim = scene.build_simulator(
        rows=cand["rows"],
        cols=cand["cols"],
        spacing=cand["spacing"],
        model=cand["model"],
        integrator=cand["integrator"],
        dt=cand["dt"],
        drag=cand["drag"],
        self_collision=False,
        **cloth,
    )
    return not sim.step_is_stable()


def changes(base: dict, batch, name: str) -> bool:
    """Whether ``batch`` sets ``name`` to a value other than ``base``'s."""
    return any(n == name and SCHEMA[n].check(v) != base[n] for n, v in batch)


def rest_spacing(cfg: dict) -> float:
    """The grid's shortest spacing at rest: its size over its cells when it has one, else the
    spacing parameter."""
    (w, h), rows, cols = cfg["size"], cfg["rows"], cfg["cols"]
    return min(w / (cols - 1), h / (rows - 1)) if w > 0 else cfg["spacing"]


def candidate(base: dict, batch) -> dict:
    """``base`` with the schema's values of a batch's parameters (its scene left out)."""
    cand = dict(base)
    for n, v in batch:
        if n in SCHEMA and n != "scene":
            cand[n] = SCHEMA[n].check(v)
    return cand


def material_refusal_is_right(cfg: dict, params, reason: str) -> bool:
    """Whether a refusal that names the material is right for ``cfg`` updated with ``params``:
    a change of what a material sets while one is in use, or a method without bending."""
    cand = dict(cfg)
    for name, value in params:
        if name in SCHEMA:
            cand[name] = SCHEMA[name].check(value)
    fabric = cand["material"] or load_scene(cand["scene"]).material is not None
    if "set by the cloth's material" in reason:
        sets = (
            "particle_mass",
            "density",
            *(f"{k}.{f}" for k in ("stiffness", "damping") for f in GRID_FAMILIES),
        )
        return bool(fabric) and any(n in sets and cand[n] != cfg[n] for n, _ in params)
    from cloth_sim.integrators import get

    return bool(fabric) and not get(cand["integrator"]).takes_bending


def runaway_is_dt_independent(node: ClothSimNode) -> bool:
    """Whether the node's last blow-up comes from the forces rather than the step: an independent
    simulator of the same cloth, material and forces, from the state the node restored, run with
    the same method at a quarter of the step, also trips the divergence guard (speed 1000 m/s) by
    twice the time the node's run took (at least 200 steps), or drives the cloth past half the
    guard's speed on the way (a 24 N wind on 19 mg particles: 790 m/s at a quarter of the step,
    450 m/s at a twentieth; the node's own step passed 1000 m/s). A wind of 400 N on 10 g particles
    does so at any dt, and so does Choi–Ko's buckling force, which jumps to 12k/L² at the onset of
    compression (rounding-level compressions on a 1.4 cm grid with a stiff bend family)."""
    cfg, node_sim = node.cfg, node.sim
    blew = re.search(
        r"the (\w+) step from .* to t=([-+0-9.e]+) s .* with dt=([-+0-9.e]+) s", node.error or ""
    )
    if not blew:
        return False
    # the method and step that blew (a set may have changed them since)
    method, until, dt = blew.group(1), float(blew.group(2)), float(blew.group(3))
    span = max(until - node_sim.time, dt)
    sim = Simulator(
        node_sim.model,
        integrator=method,
        dt=max(dt / 4, 1e-7),
        gravity=cfg["gravity"],
        wind=node_sim.wind,
        drag=cfg["drag"],
        strain_limit=cfg["strain_limit"] or None,
        strain_limit_passes=cfg["strain_limit_passes"],
        colliders=node.scene.make_colliders(),
        thickness=cfg["thickness"],
        self_collision=cfg["self_collision"],
    )
    for f in GRID_FAMILIES if sim.model.meta.get("material") is None else ():
        if (sim.model.family == sim.model.family_index(f)).any():
            sim.set_stiffness(f, cfg[f"stiffness.{f}"])
            sim.set_damping(f, cfg[f"damping.{f}"])
    sim.positions, sim.velocities = node_sim.positions, node_sim.velocities
    fastest = 0.0
    try:
        for _ in range(min(20000, max(200, math.ceil(2 * span / sim.dt)))):
            sim.step()
            fastest = max(fastest, float(np.max(np.abs(sim.velocities))))
    except SimulationDiverged:
        return True
    return fastest > 0.5 * sim.max_speed


def mismatches(node: ClothSimNode) -> list[str]:
    """Where the parameters, the node's configuration and the simulation disagree."""
    out, sim, cfg = [], node.sim, node.cfg
    for name in SCHEMA:
        value = node.get_parameter(name).value
        value = [float(v) for v in value] if isinstance(cfg[name], list) else value
        if value != cfg[name]:
            out.append(f"parameter {name}={value!r} but the node runs {cfg[name]!r}")
    checks = {
        "integrator": sim.integrator,
        "dt": sim.dt,
        "drag": sim.drag,
        "thickness": sim.thickness,
        "self_collision": sim.self_collision,
        "strain_limit": sim.strain_limit or 0.0,
        "gravity": list(sim.gravity),
        "strain_limit_passes": sim.strain_limit_passes,
        "strain_limit_method": sim.strain_limit_method,
        "rows": sim.model.rows,
        "cols": sim.model.cols,
        "model": sim.model.model,
    }
    for f in GRID_FAMILIES if sim.model.meta.get("material") is None else ():
        family = sim.model.family == sim.model.family_index(f)
        if family.any():  # a 2-row grid has no bend springs
            checks[f"stiffness.{f}"] = float(sim.stiffness(f)[0])
            checks[f"damping.{f}"] = float(sim._c[family][0])
    for name, running in checks.items():
        if running != cfg[name]:
            out.append(f"{name}: configured {cfg[name]!r}, running {running!r}")
    return out


def run(sets: int, seed: int, domain: int, quiet: bool = False, keep: int = 3) -> dict:
    rng = np.random.default_rng(seed)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain)
    figures = dict(
        sets=0,
        accepted=0,
        refused=0,
        crashes=0,
        hangs=0,
        slow_answers=0,
        invalid_accepted=0,
        valid_refused=0,
        unnamed_refusals=0,
        nonfinite_clouds=0,
        clouds=0,
        mismatches=0,
        unexpected_blowups=0,
        dt_independent_runaways=0,
        stability_refusals=0,
        scene_kind_refusals=0,
        camera_refusals=0,
        rate_refusals=0,
        thickness_refusals=0,
        material_refusals=0,
        topic_refusals=0,
    )
    examples: dict[str, list] = {}

    def note(kind, what):
        figures[kind] += 1
        examples.setdefault(kind, [])
        if len(examples[kind]) < keep:
            examples[kind].append(what)

    try:
        node = ClothSimNode(
            context=ctx,
            parameter_overrides=[
                Parameter("rows", value=16),
                Parameter("cols", value=16),
                Parameter("spacing", value=1 / 15),
                Parameter("publish_rate", value=RATE),
            ],
        )
        # the time the node spends in its parameter callbacks (validation, the stability analysis a
        # new material needs, a rebuild): the request's own cost, which the tick cannot overlap
        busy = [0.0]

        def timed(callback):
            def wrapper(*args):
                t = time.perf_counter()
                try:
                    return callback(*args)
                finally:
                    busy[0] += time.perf_counter() - t

            return wrapper

        for kind in ("pre_set", "on_set", "post_set"):  # the gate's callbacks, timed
            getattr(node, f"remove_{kind}_parameters_callback")(getattr(node.gate, kind))
            getattr(node, f"add_{kind}_parameters_callback")(timed(getattr(node.gate, kind)))
        probe = rclpy.create_node("fuzz_probe", context=ctx)
        stats, clouds = [], []
        # id(stats message) -> when the probe received it (the node may stamp sim time)
        arrived = {}

        def on_stats(msg):
            arrived[id(msg)] = time.monotonic()
            stats.append(msg)

        probe.create_subscription(Stats, "/cloth_sim/stats", on_stats, 100)
        probe.create_subscription(PointCloud2, "/cloth_sim/points", clouds.append, 100)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        ex.add_node(probe)
        clients = {
            srv: probe.create_client(srv, f"/cloth_sim/{name}")
            for srv, name in (
                (SetParameters, "set_parameters"),
                (SetParametersAtomically, "set_parameters_atomically"),
                (SetBool, "pause"),
                (Trigger, "reset"),
            )
        }

        def spin(seconds):
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                try:
                    ex.spin_once(timeout_sec=0.005)
                except Exception as e:  # a callback raised: the node would have died
                    note("crashes", repr(e))

        def call(srv, req):
            cli = clients[srv]
            while not cli.service_is_ready():
                spin(0.01)
            fut = cli.call_async(req)
            t = time.monotonic()
            while not fut.done():
                spin(0.002)
                if time.monotonic() - t > 10:
                    note("hangs", f"{srv.__name__} unanswered for 10 s")
                    return None
            return fut.result()

        spin(2.0)
        start_cfg = dict(node.cfg)
        last_blowup_ok = False  # whether the current blow-up was licensed by allow_unstable
        for i in range(sets):
            params = Generator(rng, node).params()
            atomic = bool(rng.random() < 0.5)
            msgs = []
            for name, value in params:
                v = _value_msg(value)
                msgs.append(ParameterMsg(name=name, value=v))
            # a fresh ~/stats just before the request: the interval measured below is the
            # request's, not the time this harness spent on its own checks (they block the executor
            # too)
            base = len(stats)
            wait_end = time.monotonic() + 3.0 / node.cfg["publish_rate"] + 0.2
            while len(stats) <= base and time.monotonic() < wait_end:
                spin(0.002)
            n_stats = len(stats)
            before_cfg = dict(node.cfg)
            busy[0] = 0.0
            if atomic:
                res = call(
                    SetParametersAtomically, SetParametersAtomically.Request(parameters=msgs)
                )
                results = [res.result] * len(params) if res else []
            else:
                res = call(SetParameters, SetParameters.Request(parameters=msgs))
                results = list(res.results) if res else []
            figures["sets"] += 1
            if not results:
                continue
            names = {n for n, _ in params}
            rebuilt = node.cfg.get("scene") != before_cfg.get("scene") or any(
                node.cfg[k] != before_cfg[k] for k in MODEL_KEYS
            )
            # at least one tick must follow (a paused node ticks too), within 3 ticks' time
            wait_end = time.monotonic() + 3.0 / node.cfg["publish_rate"] + 0.2
            while len(stats) <= n_stats and time.monotonic() < wait_end:
                spin(0.002)
            if len(stats) <= n_stats:
                note("hangs", (params, "no ~/stats after the request"))
            elif not rebuilt and n_stats > 0:
                if busy[0] > 0.1:
                    note(
                        "slow_answers",
                        (
                            params,
                            f"{busy[0]:.3f} s in the parameter callbacks",
                            node.cfg["integrator"],
                            f"{node.cfg['rows']}×{node.cfg['cols']}",
                        ),
                    )
                stamps = [arrived[id(s)] for s in stats[n_stats - 1 :]]
                period = 1.0 / min(node.cfg["publish_rate"], before_cfg["publish_rate"])
                window = stats[n_stats - 1 :]
                # a tick steps within its budget (0.8 of a period), stopping before a step it
                # predicts would end past it, but it cannot cut a step short: a step longer than
                # predicted (or a one-step tick) stretches the interval by up to its own length
                # (reported as overruns and a real-time factor below 1). What is left of the
                # interval, period + budget at most, is the node's: over 2 periods is a hang
                longest_step = max(
                    [s.step_time_max for s in window]
                    + [s.tick_wall_time for s in window if s.steps <= 1]
                )
                gap = (
                    max(b - a for a, b in zip(stamps, stamps[1:])) - busy[0] - longest_step
                ) / period
                if gap > HANG_TICKS:
                    note(
                        "hangs",
                        (
                            params,
                            f"{gap:.1f} ticks",
                            node.cfg["integrator"],
                            f"tick_wall max {max(s.tick_wall_time for s in window):.3f} s, "
                            f"step_max {max(s.step_time_max for s in window):.3f} s, "
                            f"steps {[s.steps for s in window]}",
                            _changed(before_cfg, start_cfg),
                        ),
                    )
            running = dict(
                before_cfg
            )  # a non-atomic request applies its members one after the other
            for (name, value), r in zip(params, results):
                valid = schema_valid(name, value)
                if r.successful:
                    figures["accepted"] += 1
                    if not valid:
                        note("invalid_accepted", (name, value))
                    elif name in SCHEMA and name != "scene":
                        running[name] = SCHEMA[name].check(value)
                    continue
                figures["refused"] += 1
                if not any(
                    r.reason.startswith(n) or f" {n} " in r.reason or n in r.reason for n in names
                ):
                    note("unnamed_refusals", (name, value, r.reason))
                everything_valid = all(
                    schema_valid(n, v) for n, v in (params if atomic else [(name, value)])
                )
                if everything_valid and name in SCHEMA:
                    if "above the stable limit" in r.reason or "buckling onset load" in r.reason:
                        figures["stability_refusals"] += 1
                        batch = (
                            [(n, v) for n, v in params if n != "scene"]
                            if atomic
                            else [(name, value)]
                        )
                        if "scene" not in names and not limit_refusal_is_right(
                            before_cfg if atomic else running, batch
                        ):
                            note("valid_refused", (params, r.reason))
                    elif "cannot be met" in r.reason:
                        figures["rate_refusals"] += 1
                    elif "camera.far" in r.reason or "camera.look_at must be a point" in r.reason:
                        # the camera's combinations: right only when the camera is on and its far
                        # is not above its near, or it looks at its own position
                        figures["camera_refusals"] += 1
                        cand = candidate(
                            before_cfg if atomic else running,
                            params if atomic else [(name, value)],
                        )
                        if "scene" not in names and not (
                            cand["camera.enable"]
                            and (
                                cand["camera.far"] <= cand["camera.near"]
                                or cand["camera.position"] == cand["camera.look_at"]
                            )
                        ):
                            note("valid_refused", (params, r.reason))
                    elif "particle_mass: set by scene" in r.reason:
                        # a grid given by its mass per area (fold): right only when the batch
                        # changes particle_mass on such a scene
                        figures["scene_kind_refusals"] += 1
                        base = before_cfg if atomic else running
                        batch = params if atomic else [(name, value)]
                        if "scene" not in names and not (
                            load_scene(base["scene"]).grid_density is not None
                            and changes(base, batch, "particle_mass")
                        ):
                            note("valid_refused", (params, r.reason))
                    elif "not used by scene" in r.reason:
                        # a mesh's density on a grid (the fuzz's scenes are grids): right only when
                        # the batch changes it
                        figures["scene_kind_refusals"] += 1
                        base = before_cfg if atomic else running
                        batch = params if atomic else [(name, value)]
                        if "scene" not in names and not changes(base, batch, "density"):
                            note("valid_refused", (params, r.reason))
                    elif "too thick for self_collision" in r.reason:
                        figures["thickness_refusals"] += 1
                        cand = candidate(
                            before_cfg if atomic else running,
                            params if atomic else [(name, value)],
                        )
                        if "scene" not in names and not (
                            cand["self_collision"]
                            and cand["thickness"] > 0.5 * rest_spacing(cand) * (1 + 1e-9)
                        ):
                            note("valid_refused", (params, r.reason))
                    elif "material" in r.reason and (
                        "set by the cloth's material" in r.reason
                        or "does not take a material's bending" in r.reason
                    ):
                        figures["material_refusals"] += 1
                        batch = params if atomic else [(name, value)]
                        base = before_cfg if atomic else running
                        if "scene" not in names and not material_refusal_is_right(
                            base,
                            [(n, v) for n, v in batch if n in SCHEMA and n != "scene"],
                            r.reason,
                        ):
                            note("valid_refused", (params, r.reason))
                    elif "are the same topic" in r.reason:
                        figures["topic_refusals"] += 1
                        cand = candidate(
                            before_cfg if atomic else running,
                            params if atomic else [(name, value)],
                        )
                        same = cand["robot.description_topic"].lstrip("/") == cand[
                            "robot.joint_states_topic"
                        ].lstrip("/")
                        if "scene" not in names and not (cand["robot.enable"] and same):
                            note("valid_refused", (params, r.reason))
                    elif name == "scene" or "scene" in names:
                        # a scene that exists but whose values this batch contradicts, or
                        # unloadable
                        pass
                    else:
                        note("valid_refused", (params, r.reason))
            if any(r.successful for r in results):
                for m in mismatches(node):
                    note("mismatches", (params, m))
                if any(n == "allow_unstable" and v is True for n, v in params):
                    last_blowup_ok = True
            spin(0.02)
            if node.error:
                if not (last_blowup_ok or node.cfg["allow_unstable"]):
                    if runaway_is_dt_independent(node):
                        note(
                            "dt_independent_runaways",
                            (params, node.error[:200], _changed(node.cfg, start_cfg)),
                        )
                    else:
                        note(
                            "unexpected_blowups",
                            (params, node.error[:200], _changed(node.cfg, start_cfg)),
                        )
                call(Trigger, Trigger.Request()) if rng.random() < 0.5 else call(
                    SetBool, SetBool.Request(data=False)
                )
                last_blowup_ok = node.cfg["allow_unstable"]
            if node.paused and not node.error:
                call(SetBool, SetBool.Request(data=False))
            for c in clouds:
                figures["clouds"] += 1
                if not np.all(np.isfinite(np.frombuffer(bytes(c.data), dtype=np.float32))):
                    note("nonfinite_clouds", params)
            clouds.clear()
            for s_ in stats[:-5]:
                arrived.pop(id(s_), None)
            del stats[:-5]
            if not quiet and (i + 1) % 500 == 0:
                print(f"{i + 1} sets: {figures}", flush=True)
        ex.shutdown()
        probe.destroy_node()
        node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)
    figures["examples"] = examples
    return figures


FAILURES = (
    "crashes",
    "hangs",
    "slow_answers",
    "invalid_accepted",
    "valid_refused",
    "unnamed_refusals",
    "nonfinite_clouds",
    "mismatches",
    "unexpected_blowups",
)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sets", type=int, default=5000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument(
        "--examples", type=int, default=3, help="examples kept of each kind (default 3)"
    )
    ap.add_argument("--domain", type=int, default=int(os.environ.get("ROS_DOMAIN_ID", "97")))
    args = ap.parse_args(argv)
    t = time.monotonic()
    figures = run(args.sets, args.seed, args.domain, keep=args.examples)
    examples = figures.pop("examples")
    print(
        f"# cloth_sim_node fuzz: {figures['sets']} parameter sets, seed {args.seed}, "
        f"{time.monotonic() - t:.0f} s"
    )
    for key, value in figures.items():
        print(f"{key:>20}: {value}")
    for key, items in examples.items():
        for item in items:
            print(f"  e.g. {key}: {str(item)[:1200]}")
    return 1 if any(figures[k] for k in FAILURES) else 0


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    sys.exit(main())
