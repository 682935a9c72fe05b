"""The parameter gate: every value set on the node passes here, as rclpy intends it (ros2/demos
``set_parameters_callback.py``). The pre-set callback expands a scene change into the scene's
values and turns values the schema takes but rclpy's types would not (an integer for a double, an
integer array for a double array) into the declared type; the on-set callback validates the whole
batch with no side effects (the stability analysis it needs is computed once per material and kept,
:mod:`cloth_sim.physics.stability`); the post-set callback applies it, live or by rebuilding the
cloth.
"""

from __future__ import annotations

import gc

from rcl_interfaces.msg import SetParametersResult
from rclpy.exceptions import ParameterException
from rclpy.parameter import Parameter

from .. import settings, simulator_options
from ..parameters import SCHEMA, VECTORS
from ..scene import SceneError, load_scene
from ..settings import MODEL_KEYS
from . import params as P
from .session import Session

#: a publish_rate is refused only when the measured cost exceeds the time available this many times
RATE_REFUSAL_LOAD = 10.0


def _startup_value(name, value):
    value, reason = P.check_value(name, value)
    if reason:
        raise StartupError(reason)
    return value


def settle_garbage() -> None:
    """Collect once and move every object alive now to the collector's permanent generation.

    Python's full (generation-2) collection walks every tracked object: after start-up (rclpy,
    numba, scipy, the model) that is ~140,000 objects, which, whenever the collector chose to run
    it, stalled a tick by several periods (docs/BENCHMARKS.md §7). Frozen objects are not walked,
    so a later full collection only sees what was made since. Called at start-up and after a
    rebuild (the objects a new simulation keeps); garbage is collected first, so nothing
    collectable is frozen."""
    gc.collect()
    gc.freeze()


def as_declared(p: Parameter) -> Parameter:
    """An integer given for a double parameter (``ros2 param set /cloth_sim dt 1``), as a double,
    and an integer array for a double array (``gravity: [0, 0, -9]`` in a params file), as a double
    array: the schema accepts them, rclpy's type check would not (its refusal names no
    parameter)."""
    spec = SCHEMA.get(p.name)
    if spec is not None and spec.type is float and p.type_ == Parameter.Type.INTEGER:
        return Parameter(p.name, value=float(p.value))
    if spec is not None and spec.type in VECTORS and p.type_ == Parameter.Type.INTEGER_ARRAY:
        return Parameter(p.name, value=[float(v) for v in p.value])
    return p


def _hashable(value):
    """A parameter value as part of a dict key (a vector parameter is a list)."""
    return tuple(value) if isinstance(value, list) else value


#: the share of an explicit method's stable step a scene's refused step is carried at (_carry)
CARRY_SHARE = 0.9


class StartupError(ValueError):
    """A value the node cannot start with; one line naming it."""


class ParameterGate:
    """The node's parameters: declared from the start-up values (:meth:`__init__` checks them
    whole, then builds the :attr:`session`), then every change through rclpy's three callbacks,
    registered by :meth:`open` once the parts a change drives exist (``manipulation``'s topics
    follow a new scene, ``publishing``'s frames and camera the new values, ``ticker`` a new
    rate)."""

    def __init__(self, node, overrides: dict):
        self.node = node
        self._ready = False
        self._models = {}  # rebuild key -> model (a scene's model at a size), last few kept
        self._validated = None  # what the on-set callback checked, for the post-set callback
        self._gate_errors: list[str] = []  # found by the pre-set callback, reported by on-set
        # the scene first: it provides the other parameters' defaults
        scene_name = _startup_value("scene", overrides.get("scene", "hanging"))
        try:
            scene = load_scene(scene_name)
        except SceneError as e:
            raise StartupError(f"scene: {e}") from None
        values = {name: overrides[name] for name in SCHEMA if name in overrides}
        try:  # the values checked whole, on the model they build (settings.check: one pass)
            checked = settings.check(scene, values, model=self._model)
        except settings.Refusal as e:
            checked = self._carry(scene, values, e)
        except ValueError as e:
            raise StartupError(str(e)) from None
        defaults = P.defaults(scene)
        # where the scene's step or its strain limit's method was carried (_carry)
        for name in ("integrator", "dt", "strain_limit_method"):
            if name not in overrides:
                defaults[name] = checked.cfg[name]
        for name in SCHEMA:  # declared once the values are known to be good
            try:
                node.declare_parameter(
                    name,
                    defaults[name] if name != "scene" else scene_name,
                    P.descriptor(SCHEMA[name]),
                )
            except ParameterException:  # e.g. an integer for a double: rclpy's types are strict
                raise StartupError(
                    f"{name} = {overrides.get(name)!r} is not accepted: expected "
                    f"{SCHEMA[name].range_text()}, as a ROS {P.type_name(SCHEMA[name])} (write "
                    f"1.0, not 1, for a double)"
                ) from None
        cfg = checked.cfg
        if cfg["device"] != node.get_parameter("device").value:  # carried to the cpu (_carry)
            node.set_parameters([Parameter("device", value=cfg["device"])])
        self.session = Session(scene, cfg, settings.build(checked), checked.stable_dt)
        self._rates_run = {cfg["publish_rate"]}  # rates the node has run with: never refused

    def _carry(self, scene, values: dict, refused: settings.Refusal) -> settings.Checked:
        """The scene's own step refused for the cloth asked for (a material, a finer grid: the
        scene's explicit method above its stable step), with neither the method nor ``dt`` given:
        the same method at :data:`CARRY_SHARE` of its stable step, or ``vbd`` where the method
        has no stable step; the scene's strain limit method not on the ``device`` asked for (the
        projection on cuda), and not given: that device with Provot's passes; a ``device`` that
        cannot run here or cannot run the scene: the cpu. Each said in the log. Any other refusal
        stops the start-up as before."""
        if (
            "strain_limit_method" in refused.named
            and "strain_limit_method" not in values
            and "device" in values
        ):
            # the scene's strain limit method is not on the device asked for: that device with
            # Provot's passes, which every device runs (and its step carried below if need be)
            how = (
                f"running on {values['device']} with Provot's passes (strain_limit_method provot)"
            )
            values = {**values, "strain_limit_method": "provot"}
            checked, refused = self._again(scene, values, refused, how)
            if checked is not None:
                return checked
        if "device" in refused.named and values.get("device", "cpu") != "cpu":
            # a device that cannot run here, or cannot run this scene: the cpu instead
            values = {**values, "device": "cpu"}
            checked, refused = self._again(scene, values, refused, "running on the cpu")
            if checked is not None:
                return checked
        if refused.named != ("dt",) or "dt" in values or "integrator" in values:
            raise StartupError(str(refused)) from None
        try:
            limit = settings.check(
                scene, {**values, "allow_unstable": True}, model=self._model
            ).stable_dt
            carried = dict(values)
            if 0.0 < limit < float("inf"):
                carried["dt"] = CARRY_SHARE * limit
            else:
                carried["integrator"] = "vbd"
            checked = settings.check(scene, carried, model=self._model)
        except ValueError:
            raise StartupError(str(refused)) from None
        cfg = checked.cfg
        how = (
            f"running {cfg['integrator']} at dt={cfg['dt']:.4g} s ({CARRY_SHARE:.0%} of its "
            f"stable step)"
            if "dt" in carried
            else f"running vbd (unconditionally stable) at dt={cfg['dt']:g} s"
        )
        self.node.get_logger().warning(f"scene {scene.name}: {refused}. Instead: {how}")
        return checked

    def _again(self, scene, values: dict, refused: settings.Refusal, how: str):
        """``values`` checked again in place of those ``refused`` (the log says so, and ``how``
        the node runs instead): ``(the checked values, refused)``, or ``(None, the new
        refusal)``; any other error stops the start-up."""
        self.node.get_logger().warning(f"scene {scene.name}: {refused}. Instead: {how}")
        try:
            return settings.check(scene, values, model=self._model), refused
        except settings.Refusal as e:
            return None, e
        except ValueError as e:
            raise StartupError(str(e)) from None

    def open(self, manipulation, publishing, ticker, robot_state) -> None:
        """Take changes from now on."""
        self.manipulation, self.publishing, self.ticker = manipulation, publishing, ticker
        self.robot_state = robot_state
        self.node.add_pre_set_parameters_callback(self.pre_set)
        self.node.add_on_set_parameters_callback(self.on_set)
        self.node.add_post_set_parameters_callback(self.post_set)
        self._ready = True

    def _model(self, cfg: dict, scene):
        """The model for ``cfg``'s rebuild values (kept: validation and application share it)."""
        key = (scene.source, *(_hashable(cfg[k]) for k in MODEL_KEYS))
        model = self._models.get(key)
        if model is None:
            model = settings.build_model(cfg, scene)
            if len(self._models) >= 4:
                self._models.pop(next(iter(self._models)))
            self._models[key] = model
        return model

    def pre_set(self, parameters: list[Parameter]) -> list[Parameter]:
        """The gate every value passes first (it runs before rclpy's own type and range checks,
        whose refusals do not name the parameter): a value the schema refuses is noted, and stands
        in the batch as the parameter's current value, so that the on-set callback refuses the
        batch with the schema's reason. A scene change brings the scene's values for every
        parameter the batch does not set."""
        self._gate_errors = []
        gated = []
        for p in parameters:
            reason = self._gate(p)
            if reason:
                self._gate_errors.append(reason)
                # a stand-in that passes rclpy's checks, so the on-set callback gives the reason
                # (an unknown name would raise before it, with an empty list in rclpy 7.1's text)
                gated.append(
                    self.node.get_parameter(
                        p.name if self.node.has_parameter(p.name) else "frame_id"
                    )
                )
                continue
            gated.append(as_declared(p))
        parameters = gated
        if self._gate_errors:
            return parameters
        scene = next((p for p in parameters if p.name == "scene"), None)
        if (
            scene is None
            or scene.value == self.session.cfg["scene"]
            or not isinstance(scene.value, str)
        ):
            return parameters
        try:
            new = load_scene(scene.value)
        except SceneError:
            return parameters  # the on-set callback refuses it with the reason
        named = {p.name for p in parameters}
        return list(parameters) + [
            Parameter(k, value=v) for k, v in new.parameter_values().items() if k not in named
        ]

    def _gate(self, p: Parameter) -> str | None:
        """The schema's reason to refuse ``p`` (or the declared type's, for rclpy's own
        parameters), ``None`` when it may go on."""
        if not self.node.has_parameter(p.name):
            return (
                f"{p.name} is not a parameter of this node; its parameters are "
                f"{', '.join(sorted(SCHEMA))}"
            )
        if p.type_ == Parameter.Type.NOT_SET:
            return f"{p.name} cannot be unset"
        if p.name in SCHEMA:
            return P.check_value(p.name, p.value)[1]
        declared = self.node.describe_parameter(p.name)
        if not declared.dynamic_typing and declared.type != p.type_.value:
            return (
                f"{p.name} = {p.value!r} is not accepted: expected a "
                f"{Parameter.Type(declared.type).name.lower()}"
            )
        return None

    def on_set(self, parameters: list[Parameter]) -> SetParametersResult:
        """Validate the whole batch; nothing changes here (the post-set callback applies it)."""
        if not self._ready:
            return SetParametersResult(successful=True)
        self._validated = None
        if self._gate_errors:
            reason, self._gate_errors = "; ".join(self._gate_errors), []
            return SetParametersResult(successful=False, reason=reason)
        cand = dict(self.session.cfg)
        for p in parameters:
            if p.name not in SCHEMA:
                continue
            value, reason = P.check_value(p.name, p.value)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
            cand[p.name] = value
        if cand == self.session.cfg:
            self._validated = (cand, None, None, self.session.stable_dt)
            return SetParametersResult(successful=True)
        scene = self.session.scene
        try:
            if cand["scene"] != self.session.cfg["scene"]:
                scene = load_scene(cand["scene"])
        except (SceneError, ValueError) as e:  # e.g. a scene whose file changed since
            return SetParametersResult(successful=False, reason=f"scene: {e}")
        rebuild = scene is not self.session.scene or any(
            cand[k] != self.session.cfg[k] for k in MODEL_KEYS
        )
        if cand["publish_rate"] not in self._rates_run:
            reason = self._check_rate(cand)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        running = self.session.sim.model
        # what the batch changes: from the running values, and on a new scene from the values it
        # brings (a fabric's scene sets no springs: moving to it from one that has them is no
        # change of theirs, a spring value given with it is)
        before = self.session.cfg
        if scene is not self.session.scene:
            before = {**before, **scene.parameter_values()}
        try:  # the batch whole, on the model it builds (settings.check: one pass)
            checked = settings.check(
                scene,
                cand,
                changes_from=before,
                model=self._model if rebuild else (lambda cfg, scene: running),
            )
        except settings.Refusal as e:
            reason = str(e)
            if e.stage == "model":  # a scene whose mesh changed since, say
                reason = f"scene: {e}"
            elif e.stage == "combination":  # named with what else the request changed
                reason = self._blame(parameters, cand, reason, e.named)
            return SetParametersResult(successful=False, reason=reason)
        model, limit = checked.model, checked.stable_dt
        self._validated = (cand, scene if rebuild else None, model if rebuild else None, limit)
        return SetParametersResult(successful=True)

    def _blame(self, parameters, cand: dict, reason: str, named: tuple) -> str:
        """``reason`` for a refusal of a combination, prefixed with the other values of the
        request that changed (``reason`` names ``named`` itself)."""
        changed = [
            p.name
            for p in parameters
            if p.name in SCHEMA
            and p.name not in named
            and cand[p.name] != self.session.cfg[p.name]
        ]
        if not changed:
            return reason
        return (
            f"{', '.join(f'{n} = {cand[n]!r}' for n in changed)}: with "
            f"{'this value' if len(changed) == 1 else 'these values'}, {reason}"
        )

    def post_set(self, parameters: list[Parameter]) -> None:
        """Apply what :meth:`on_set` accepted."""
        if not self._ready or self._validated is None:
            return
        cand, scene, model, limit = self._validated
        self._validated = None
        if scene is not None:
            self.session.replace(settings.build_simulator(cand, model, scene), scene)
            self.session.restarted()  # the new simulation has the scene's colliders only
            self.manipulation.drop_grippers()
            self.manipulation.adopt_grippers()
            self.manipulation.subscribe_colliders()
            settle_garbage()
        else:
            if cand != self.session.cfg:
                self.session.change_checkpoint = (
                    self.session.sim.time,
                    self.session.sim.save_state(),
                )
            simulator_options.apply(self.session.sim, cand, self.session.cfg)
            # what the energy means may have changed (stiffness, gravity)
            self.session.balance.restart()
        if cand["real_time_factor"] != self.session.cfg["real_time_factor"]:
            self.session.carry = 0.0  # a backlog owed at the old pace is not owed at the new one
            self.session.history.clear()
        self._rates_run.add(cand["publish_rate"])
        rate_changed = cand["publish_rate"] != self.session.cfg["publish_rate"]
        self.session.cfg = cand
        self.session.stable_dt = limit
        self.publishing.configure(cand)
        self.robot_state.configure(cand)
        if rate_changed:
            self.ticker.set_rate(cand["publish_rate"])

    def _check_rate(self, cand: dict) -> str | None:
        """A rate is refused only when the measured cost of stepping and publishing exceeds the
        time available many times over (RATE_REFUSAL_LOAD): measured costs are noisy, and a tick
        that does not fit only lowers the real-time factor (ticks are bounded, /diagnostics warns).
        A rate the node has run with is never refused."""
        if len(self.session.tick_costs) < 10:
            return None
        steps = sum(c[0] for c in self.session.tick_costs)
        step_wall = sum(c[1] for c in self.session.tick_costs)
        pub_wall = sum(c[2] for c in self.session.tick_costs) / len(self.session.tick_costs)
        per_step = step_wall / steps if steps else 0.0
        load = per_step / cand["dt"] + cand["publish_rate"] * pub_wall
        if load > RATE_REFUSAL_LOAD:
            return (
                f"publish_rate={cand['publish_rate']:g} Hz cannot be met: stepping "
                f"({1e3 * per_step:.3f} ms/step at dt={cand['dt']:g}) and publishing "
                f"({1e3 * pub_wall:.3f} ms/tick) would need {load:.2f} s of work per second; "
                f"lower publish_rate, or raise dt"
            )
        return None
