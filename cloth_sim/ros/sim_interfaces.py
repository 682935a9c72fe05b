"""The ROS simulation standard (``simulation_interfaces``, Jazzy) over the node.

Gazebo, Isaac Sim and O3DE answer the same services; cloth_sim answers them under its node's
namespace with the standard's snake_case names (``/cloth_sim/step_simulation``, …), as Gazebo does
under ``/gzserver/``. Each service is one small handler here; they reach the simulation through the
node's own operations (pause, reset, step, poses), so the package's services (``~/pause``,
``~/reset``, ``~/step``) and these stay one behaviour. ``get_simulator_features`` says what is
supported (:data:`FEATURES`); every other service of the standard exists too and answers
``RESULT_FEATURE_UNSUPPORTED`` with a message, never a time-out.

Entities: ``cloth`` (the cloth itself, CATEGORY_OBJECT), ``collider/<name>`` (the scene's
colliders, CATEGORY_STATIC_OBJECT: kinematic, moved by pose or at a set twist) and ``gripper/<name>`` (each gripper
holding the cloth, CATEGORY_ROBOT). States are in the node's ``frame_id``.

Simulation states: PLAYING (ticking), PAUSED (``~/pause``), STOPPED (reset to the start and paused;
from there PLAYING or a step goes on, PAUSED is an incorrect transition, as the standard defines).
``step_simulation`` and the ``simulate_steps`` action step only while paused or stopped.
"""

from __future__ import annotations

import re

import numpy as np
from geometry_msgs.msg import Vector3
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.task import Future

from .messages import checked_pose
from simulation_interfaces import srv
from simulation_interfaces.action import SimulateSteps
from simulation_interfaces.msg import (Bounds, EntityCategory, EntityInfo, EntityState, Result,
                                       SimulationState, SimulatorFeatures)

F = SimulatorFeatures
#: what cloth_sim supports of the standard (get_simulator_features)
FEATURES = (F.SPAWNING, F.SPAWNING_RESOURCE_STRING, F.DELETING, F.SPAWNABLES,
            F.SIMULATION_RESET_SPAWNED, F.ENTITY_STATE_GETTING, F.ENTITY_STATE_SETTING, F.ENTITY_BOUNDS, F.ENTITY_CATEGORIES,
            F.ENTITY_INFO_GETTING, F.SIMULATION_RESET, F.SIMULATION_RESET_TIME,
            F.SIMULATION_RESET_STATE, F.SIMULATION_STATE_GETTING, F.SIMULATION_STATE_SETTING,
            F.SIMULATION_STATE_PAUSE, F.STEP_SIMULATION_SINGLE, F.STEP_SIMULATION_MULTIPLE,
            F.STEP_SIMULATION_ACTION)
#: the services of the standard cloth_sim does not support (yet): they answer FEATURE_UNSUPPORTED
UNSUPPORTED = {
    "spawn_entities": srv.SpawnEntities, "set_entity_info": srv.SetEntityInfo, "get_named_poses": srv.GetNamedPoses,
    "get_named_pose_bounds": srv.GetNamedPoseBounds, "load_world": srv.LoadWorld,
    "unload_world": srv.UnloadWorld, "get_current_world": srv.GetCurrentWorld,
    "get_available_worlds": srv.GetAvailableWorlds,
}
#: the standard's reset scopes cloth_sim takes
SCOPE_ALL = srv.ResetSimulation.Request.SCOPE_ALL
CLOTH = "cloth"
#: spawn_entity's URI scheme: ``cloth_sim://<shape>?<field>=<value>&…`` (a vector as ``x,y,z``)
SCHEME = "cloth_sim"
#: what each shape needs besides its pose (initial_pose places it), with the defaults used when
#: a URI or resource does not give them
SPAWN_DEFAULTS = {"plane": {"normal": [0.0, 0.0, 1.0]}, "sphere": {"center": [0.0, 0.0, 0.0]},
                  "box": {"center": [0.0, 0.0, 0.0]}, "capsule": {}}
SPAWNABLES = {
    "sphere": "cloth_sim://sphere?radius=0.1&friction=0.3",
    "box": "cloth_sim://box?half_extents=0.2,0.2,0.02&friction=0.5",
    "capsule": "cloth_sim://capsule?a=0,0,-0.1&b=0,0,0.1&radius=0.02",
    "plane": "cloth_sim://plane?normal=0,0,1&friction=0.5",
}


def result(code: int = Result.RESULT_OK, message: str = "") -> Result:
    return Result(result=code, error_message=message)


class SimulationInterfaces:
    """Creates the standard's services and action on ``node`` (a :class:`~cloth_sim.ros.node.
    ClothSimNode`); the node calls :meth:`tick` from each tick while paused, so a
    ``simulate_steps`` goal steps within the tick's budget and reports feedback."""

    def __init__(self, node):
        self.node = node
        self.stopped = False
        #: names of the colliders spawned through spawn_entity (reset with SCOPE_SPAWNED removes them)
        self.spawned: set[str] = set()
        self._goal = None  # (goal handle, remaining steps, completed, future) of simulate_steps
        handlers = {
            "get_simulator_features": (srv.GetSimulatorFeatures, self.get_simulator_features),
            "get_simulation_state": (srv.GetSimulationState, self.get_simulation_state),
            "set_simulation_state": (srv.SetSimulationState, self.set_simulation_state),
            "reset_simulation": (srv.ResetSimulation, self.reset_simulation),
            "step_simulation": (srv.StepSimulation, self.step_simulation),
            "get_entities": (srv.GetEntities, self.get_entities),
            "get_entities_states": (srv.GetEntitiesStates, self.get_entities_states),
            "get_entity_state": (srv.GetEntityState, self.get_entity_state),
            "set_entity_state": (srv.SetEntityState, self.set_entity_state),
            "get_entity_bounds": (srv.GetEntityBounds, self.get_entity_bounds),
            "get_entity_info": (srv.GetEntityInfo, self.get_entity_info),
            "spawn_entity": (srv.SpawnEntity, self.spawn_entity),
            "delete_entity": (srv.DeleteEntity, self.delete_entity),
            "get_spawnables": (srv.GetSpawnables, self.get_spawnables),
        }
        for name, (kind, handler) in handlers.items():
            node.create_service(kind, f"~/{name}", handler)
        for name, kind in UNSUPPORTED.items():
            node.create_service(kind, f"~/{name}", self._unsupported(name))
        self.action = ActionServer(node, SimulateSteps, "~/simulate_steps", self._execute,
                                   goal_callback=lambda goal: GoalResponse.ACCEPT,
                                   cancel_callback=lambda handle: CancelResponse.ACCEPT)

    # ------------------------------------------------------------------ features and state
    def get_simulator_features(self, request, response):
        response.features.features = list(FEATURES)
        response.features.spawn_formats = ["cloth_sim_collider"]
        response.features.custom_info = ("cloth_sim: a mass-spring cloth; entities are 'cloth', "
                                         "'collider/<name>' and 'gripper/<name>'; spawn_entity takes a "
                                         "collider: uri cloth_sim://<plane|sphere|box|capsule>?"
                                         "<field>=<value>&… or resource_string, a scene's collider "
                                         "mapping in YAML; initial_pose places it")
        return response

    def state(self) -> int:
        if self.stopped:
            return SimulationState.STATE_STOPPED
        return SimulationState.STATE_PAUSED if self.node.paused else SimulationState.STATE_PLAYING

    def get_simulation_state(self, request, response):
        response.state.state = self.state()
        response.result = result()
        return response

    def set_simulation_state(self, request, response):
        S, R = SimulationState, srv.SetSimulationState.Response
        target, now = request.state.state, self.state()
        if target == now:
            response.result = result(R.ALREADY_IN_TARGET_STATE, f"already in state {target}")
        elif target == S.STATE_PLAYING:
            self.stopped = False
            self.node.set_paused(False)
            response.result = result()
        elif target == S.STATE_PAUSED:
            if now == S.STATE_STOPPED:
                response.result = result(R.INCORRECT_TRANSITION, "pausing a stopped simulation: "
                                         "play it or step it first")
            else:
                self.node.set_paused(True)
                response.result = result()
        elif target == S.STATE_STOPPED:
            self.node.reset_simulation(keep_paused=False)
            self.node.set_paused(True)
            self.stopped = True
            response.result = result()
        elif target == S.STATE_QUITTING:
            response.result = result(Result.RESULT_FEATURE_UNSUPPORTED,
                                     "cloth_sim does not quit through this service: stop its process "
                                     "(SIGINT, as ros2 launch does)")
        else:
            response.result = result(R.INCORRECT_TRANSITION,
                                     f"state {target}: cloth_sim has no worlds to load or unload")
        return response

    def reset_simulation(self, request, response):
        R = srv.ResetSimulation.Request
        scope = R.SCOPE_ALL if request.scope == R.SCOPE_DEFAULT else request.scope
        known = R.SCOPE_TIME | R.SCOPE_STATE | R.SCOPE_SPAWNED
        if scope != SCOPE_ALL and scope & ~known:
            response.result = result(Result.RESULT_FEATURE_UNSUPPORTED,
                                     f"scope {request.scope}: cloth_sim resets SCOPE_DEFAULT, "
                                     f"SCOPE_ALL and any of SCOPE_TIME, SCOPE_STATE, SCOPE_SPAWNED")
            return response
        if scope & R.SCOPE_SPAWNED:
            for name in sorted(self.spawned):
                self._remove_collider(name)
        sim = self.node.sim
        if scope & R.SCOPE_STATE:
            t = sim.time
            self.node.reset_simulation(keep_paused=True)
            if not scope & R.SCOPE_TIME:
                sim.set_time(t)
        elif scope & R.SCOPE_TIME:
            sim.set_time(0.0)
        response.result = result()
        return response

    # ------------------------------------------------------------------ stepping
    def step_simulation(self, request, response):
        if self.state() == SimulationState.STATE_PLAYING:
            response.result = result(Result.RESULT_OPERATION_FAILED,
                                     "step_simulation runs only while paused or stopped: set the "
                                     "simulation state to STATE_PAUSED first")
            return response
        ok, message = self.node.step_paused(int(request.steps))
        if ok:
            self.stopped = False
        response.result = result(Result.RESULT_OK if ok else Result.RESULT_OPERATION_FAILED, message)
        return response

    async def _execute(self, handle):
        steps = int(handle.request.steps)
        out = SimulateSteps.Result()
        if self.state() == SimulationState.STATE_PLAYING:
            handle.abort()
            out.result = result(Result.RESULT_OPERATION_FAILED,
                                "simulate_steps runs only while paused or stopped")
            return out
        if self._goal is not None:
            handle.abort()
            out.result = result(Result.RESULT_INCORRECT_STATE, "another simulate_steps goal is running")
            return out
        done = Future()
        self._goal = [handle, steps, 0, done]
        self.stopped = False
        return await done

    @property
    def busy(self) -> bool:
        """Whether a ``simulate_steps`` goal is running."""
        return self._goal is not None

    def tick(self, t0: float, budget: float) -> tuple[int, float, float]:
        """Advance the running ``simulate_steps`` goal within this tick's budget (the node is
        paused); returns ``(steps, step wall, longest)`` for the tick's stats."""
        handle, remaining, completed, done = self._goal
        out = SimulateSteps.Result()
        if handle.is_cancel_requested:
            handle.canceled()
            out.result = result(Result.RESULT_OPERATION_FAILED,
                                f"canceled after {completed} of {completed + remaining} steps")
            self._finish(out)
            return 0, 0.0, 0.0
        steps, wall, longest, message = self.node.step_within(remaining, t0, budget)
        if steps is None:  # it diverged: the node went back and paused (its message says how)
            handle.abort()
            out.result = result(Result.RESULT_OPERATION_FAILED, message)
            self._finish(out)
            return 0, 0.0, 0.0
        remaining, completed = remaining - steps, completed + steps
        self._goal[1:3] = [remaining, completed]
        handle.publish_feedback(SimulateSteps.Feedback(completed_steps=completed,
                                                       remaining_steps=remaining))
        if remaining == 0:
            handle.succeed()
            out.result = result(Result.RESULT_OK, f"{completed} steps")
            self._finish(out)
        return steps, wall, longest

    def _finish(self, out) -> None:
        done = self._goal[3]
        self._goal = None
        done.set_result(out)

    # ------------------------------------------------------------------ entities
    def entities(self) -> dict:
        """``{name: (category, description)}`` of every entity now."""
        sim = self.node.sim
        out = {CLOTH: (EntityCategory.CATEGORY_OBJECT,
                       f"the cloth: {sim.model.n_particles} particles, {len(sim.model.triangles)} "
                       f"triangles")}
        for c in sim.colliders:
            out[f"collider/{c.name}"] = (EntityCategory.CATEGORY_STATIC_OBJECT,
                                         f"a {type(c).__name__.lower()} collider (kinematic)")
        for name in sim.grippers:
            out[f"gripper/{name}"] = (EntityCategory.CATEGORY_ROBOT,
                                      f"a gripper holding {len(sim.grippers[name])} particles")
        return out

    def _matching(self, filters) -> tuple[list[str] | None, Result]:
        if filters.tags.tags:
            return None, result(Result.RESULT_FEATURE_UNSUPPORTED, "cloth_sim's entities have no tags")
        if filters.bounds.type != Bounds.TYPE_EMPTY or filters.bounds.points:
            return None, result(Result.RESULT_FEATURE_UNSUPPORTED,
                                "filtering by bounds is not supported (get_entity_bounds is)")
        try:
            pattern = re.compile(filters.filter)
        except re.error as e:
            return None, result(Result.RESULT_OPERATION_FAILED,
                                f"filters.filter = {filters.filter!r} is not a regular expression ({e})")
        categories = {c.category for c in filters.categories}
        names = [n for n, (cat, _) in self.entities().items()
                 if pattern.search(n) and (not categories or cat in categories)]
        return names, result()

    def get_entities(self, request, response):
        names, response.result = self._matching(request.filters)
        response.entities = names or []
        return response

    def get_entities_states(self, request, response):
        names, response.result = self._matching(request.filters)
        response.entities = names or []
        response.states = [self._state(n) for n in response.entities]
        return response

    def _collider_index(self, name: str) -> int | None:
        """The index in ``sim.colliders`` of the collider called ``name`` (``None``: none is)."""
        return next((i for i, c in enumerate(self.node.sim.colliders) if c.name == name), None)

    def _unknown(self, name: str) -> Result:
        return result(Result.RESULT_NOT_FOUND, f"no entity {name!r}; entities: "
                      f"{', '.join(self.entities())}")

    def _state(self, name: str) -> EntityState:
        sim, node = self.node.sim, self.node
        state = EntityState()
        state.header.frame_id = node.cfg["frame_id"]
        state.header.stamp = node.stamp()
        if name == CLOTH:  # its frame: the node's frame_id; its twist: the centre of mass's
            m = sim.model.masses
            v = (m @ sim.velocities) / m.sum()
            state.pose.orientation.w = 1.0
            state.twist.linear = Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))
            return state
        kind, _, key = name.partition("/")
        if kind == "collider":
            c = sim.colliders[self._collider_index(key)]
            p, q = c.position, c.orientation
        else:
            p, q = sim.gripper_pose(key)
        v, w = node.twist(kind, key)
        state.twist.linear = _vec(v)
        state.twist.angular = _vec(w)
        state.pose.position.x, state.pose.position.y, state.pose.position.z = (float(a) for a in p)
        (state.pose.orientation.w, state.pose.orientation.x, state.pose.orientation.y,
         state.pose.orientation.z) = (float(a) for a in q)
        return state

    def get_entity_state(self, request, response):
        if request.entity not in self.entities():
            response.result = self._unknown(request.entity)
            return response
        response.state = self._state(request.entity)
        response.result = result()
        return response

    def set_entity_state(self, request, response):
        name, state = request.entity, request.state
        if name not in self.entities():
            response.result = self._unknown(name)
            return response
        if name == CLOTH:
            response.result = result(Result.RESULT_OPERATION_FAILED,
                                     "the cloth's state is its particles': move it with its grippers "
                                     "(gripper/<name>) or grasp it (~/grasp)")
            return response
        position, orientation, problem = checked_pose(state.pose, state.header.frame_id,
                                                      self.node.cfg["frame_id"], prefix="state.")
        t = state.twist
        linear = np.array([t.linear.x, t.linear.y, t.linear.z])
        angular = np.array([t.angular.x, t.angular.y, t.angular.z])
        if problem is None and not (np.all(np.isfinite(linear)) and np.all(np.isfinite(angular))):
            problem = (f"state.twist = {linear.tolist()}, {angular.tolist()}: expected finite "
                       f"linear and angular velocities")
        if problem:
            response.result = result(srv.SetEntityState.Response.INVALID_POSE, problem)
            return response
        kind, _, key = name.partition("/")
        sim = self.node.sim
        if kind == "collider":
            sim.set_collider_pose(self._collider_index(key), position, orientation)
        else:
            sim.set_gripper_pose(key, position, orientation)
        self.node.set_twist(kind, key, linear, angular)  # kinematic: it keeps this velocity
        response.result = result()
        return response

    def spawn_entity(self, request, response):
        """A collider from ``uri`` (``cloth_sim://<shape>?…``) or ``resource_string`` (YAML: a
        scene's collider mapping), placed at ``initial_pose``."""
        code, message, collider = self._collider_from(request)
        if collider is None:
            response.result = result(code, message)
            return response
        self.node.sim.add_collider(collider)
        self.spawned.add(collider.name)
        self.node.colliders_changed()
        response.entity_name = f"collider/{collider.name}"
        response.result = result(Result.RESULT_OK, f"spawned {type(collider).__name__.lower()} "
                                 f"{response.entity_name}")
        return response

    def _collider_from(self, request):
        """``(code, message, collider)``: the collider a spawn request describes, or the standard's
        code and the reason (collider ``None``)."""
        import yaml

        from ..colliders import KINDS
        from ..scene import SceneError, _Validator

        R = srv.SpawnEntity.Response
        if not request.uri and not request.resource_string:
            return R.NO_RESOURCE, "give uri (cloth_sim://<shape>?…) or resource_string (YAML)", None
        if request.entity_namespace:
            return (R.NAMESPACE_INVALID, f"entity_namespace = {request.entity_namespace!r}: a "
                    f"collider has no interfaces to put under a namespace; leave it empty", None)
        if request.uri:
            spec = _parse_uri(request.uri)
            if isinstance(spec, str):
                return R.UNSUPPORTED_FORMAT, spec, None
        else:
            try:
                spec = yaml.safe_load(request.resource_string)
            except yaml.YAMLError as e:
                return R.RESOURCE_PARSE_ERROR, f"resource_string is not YAML ({e})", None
            if not isinstance(spec, dict) or spec.get("type") not in SPAWN_DEFAULTS:
                return (R.UNSUPPORTED_FORMAT, "resource_string must be a mapping with type: plane, "
                        "sphere, box or capsule, and that shape's fields", None)
        kind = spec["type"]
        spec = {**SPAWN_DEFAULTS[kind], **spec}
        names = {c.name for c in self.node.sim.colliders}
        name = request.name or f"{kind}_{len(names)}"
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]{0,63}", name):
            return (R.NAME_INVALID, f"name = {name!r}: expected ASCII letters, digits and _ (not "
                    f"starting with a digit, at most 64): it names the collider's topic and frame", None)
        if name in names:
            if not request.allow_renaming:
                return R.NAME_NOT_UNIQUE, f"a collider named {name!r} exists (allow_renaming: false)", None
            name = next(f"{name}_{k}" for k in range(1, len(names) + 2) if f"{name}_{k}" not in names)
        spec["name"] = name
        try:
            kind, kw = _Validator("spawn_entity").collider(0, spec)
        except SceneError as e:
            return R.RESOURCE_PARSE_ERROR, str(e).replace("colliders[0].", ""), None
        position, orientation, problem = checked_pose(request.initial_pose.pose,
                                                      request.initial_pose.header.frame_id,
                                                      self.node.cfg["frame_id"], prefix="initial_pose.")
        if problem:
            return R.INVALID_POSE, problem, None
        collider = KINDS[kind](**kw)
        # the pose: a sphere's or box's centre, a capsule's midpoint, a point on a plane (the
        # identity orientation keeps a plane's normal and a capsule's segment as built)
        collider.set_pose(position, orientation)
        return Result.RESULT_OK, "", collider

    def delete_entity(self, request, response):
        name = request.entity
        entities = self.entities()
        if name not in entities:
            response.result = self._unknown(name)
        elif name == CLOTH:
            response.result = result(Result.RESULT_OPERATION_FAILED, "the cloth cannot be deleted "
                                     "(a scene change replaces it)")
        elif name.startswith("gripper/"):
            self.node.release_gripper(name.partition("/")[2])
            response.result = result(Result.RESULT_OK, f"{name} released the cloth")
        else:
            self._remove_collider(name.partition("/")[2])
            response.result = result()
        return response

    def _remove_collider(self, name: str) -> None:
        sim = self.node.sim
        index = self._collider_index(name)
        if index is not None:
            sim.remove_collider(index)
            self.node.colliders_changed()
        self.spawned.discard(name)

    def get_spawnables(self, request, response):
        from simulation_interfaces.msg import Spawnable

        if request.sources:
            response.result = result(Result.RESULT_FEATURE_UNSUPPORTED,
                                     "cloth_sim's spawnables are its collider shapes: no sources")
            return response
        response.spawnables = [Spawnable(uri=uri, description=f"a {kind} collider (fields as in a "
                                         f"scene file; initial_pose places it)")
                               for kind, uri in SPAWNABLES.items()]
        response.result = result()
        return response

    def get_entity_bounds(self, request, response):
        name = request.entity
        if name not in self.entities():
            response.result = self._unknown(name)
            return response
        sim = self.node.sim
        kind, _, key = name.partition("/")
        b = Bounds()
        if name == CLOTH:
            pts = sim.positions
        elif kind == "gripper":
            pts = sim.positions[sim.grippers[key]]
        else:
            pts = collider_extent(sim.colliders[self._collider_index(key)])
        if pts is None:
            b.type = Bounds.TYPE_EMPTY  # an infinite plane
        elif isinstance(pts, tuple):  # a sphere: centre, then (radius, 0, 0)
            b.type = Bounds.TYPE_SPHERE
            b.points = [_vec(pts[0]), Vector3(x=float(pts[1]))]
        else:
            b.type = Bounds.TYPE_BOX
            b.points = [_vec(pts.min(axis=0)), _vec(pts.max(axis=0))]
        response.bounds = b
        response.result = result()
        return response

    def get_entity_info(self, request, response):
        entities = self.entities()
        if request.entity not in entities:
            response.result = self._unknown(request.entity)
            return response
        category, description = entities[request.entity]
        response.info = EntityInfo(category=EntityCategory(category=category), description=description)
        response.result = result()
        return response

    @staticmethod
    def _unsupported(name: str):
        def handler(request, response):
            response.result = result(Result.RESULT_FEATURE_UNSUPPORTED,
                                     f"{name} is not supported by cloth_sim (get_simulator_features "
                                     f"lists what is)")
            return response
        return handler


def collider_extent(c):
    """Points whose box bounds the collider, ``(centre, radius)`` for a sphere, ``None`` for a
    plane (unbounded)."""
    from ..colliders import Box, Capsule, Sphere

    if isinstance(c, Sphere):
        return (c.center, c.radius)
    if isinstance(c, Box):
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        return (corners * c.half_extents) @ c.rotation.T + c.center
    if isinstance(c, Capsule):
        ends = np.stack([c.a, c.b])
        return np.concatenate([ends - c.radius, ends + c.radius])
    return None


def _vec(a) -> Vector3:
    return Vector3(x=float(a[0]), y=float(a[1]), z=float(a[2]))


def _parse_uri(uri: str):
    """``{type, fields…}`` of a ``cloth_sim://<shape>?<field>=<value>&…`` URI (numbers, and vectors
    as ``x,y,z``), or the reason it is not one (a string)."""
    from urllib.parse import parse_qsl

    # (by hand: an underscore is no URI scheme character for urllib)
    shape, _, query = uri[len(SCHEME) + 3:].partition("?")
    if not uri.startswith(f"{SCHEME}://") or shape not in SPAWN_DEFAULTS:
        return (f"uri = {uri!r}: expected {SCHEME}://<shape>?<field>=<value>&… with shape one of "
                f"{', '.join(SPAWN_DEFAULTS)} (get_spawnables lists examples)")
    spec = {"type": shape}
    for key, value in parse_qsl(query, keep_blank_values=True):
        try:
            numbers = [float(v) for v in value.split(",")]
        except ValueError:
            return f"uri field {key} = {value!r}: expected a number or numbers separated by commas"
        spec[key] = numbers[0] if len(numbers) == 1 else numbers
    return spec
