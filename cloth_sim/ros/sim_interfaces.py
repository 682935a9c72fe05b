"""The ROS simulation standard (``simulation_interfaces``, Jazzy) over the node.

Gazebo, Isaac Sim and O3DE answer the same services; cloth_sim answers them under its node's
namespace with the standard's snake_case names (``/cloth_sim/step_simulation``, …), as Gazebo does
under ``/gzserver/``. Each service is one small handler here; they reach the simulation through the
node's own operations (pause, reset, step, poses), so the package's services (``~/pause``,
``~/reset``, ``~/step``) and these stay one behaviour. ``get_simulator_features`` says what is
supported (:data:`FEATURES`); every other service of the standard exists too and answers
``RESULT_FEATURE_UNSUPPORTED`` with a message, never a time-out.

Entities, their names, categories and bounds: :mod:`cloth_sim.ros.entities`. A client may address
an entity by the name it gave at spawn or by the full name the response returned. States are in the
node's ``frame_id``; a pose may also be given in its ``world_frame_id`` (``/tf_static`` makes them
one frame) or with an empty frame (the standard's default).

``set_entity_state`` sets a state, as the standard says: a pose is a teleport (the entity is there
at once and at rest; the cloth is not dragged, and what a collider now overlaps is pushed out at
the next step), a twist is what the entity then moves at — refused for a static object (a collider
unless ``set_entity_info`` made it, say, a DYNAMIC_OBJECT). Streaming poses on
``~/colliders/<name>/pose`` keeps its swept motion (friction drags what rests on the collider).

Simulation states: PLAYING (ticking), PAUSED (``~/pause``), STOPPED (reset to the start and paused;
from there PLAYING or a step goes on, PAUSED is an incorrect transition, as the standard defines).
``step_simulation`` and the ``simulate_steps`` action step only while paused or stopped.
``reset_simulation`` returns the scene: the cloth, its grippers, its colliders where it puts them
(moved, deleted or set moving since), without twists; SCOPE_SPAWNED removes the spawned colliders,
SCOPE_STATE alone puts them back where they were spawned.
"""

from __future__ import annotations

import itertools

import numpy as np
from geometry_msgs.msg import Vector3
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.task import Future
from simulation_interfaces import srv
from simulation_interfaces.action import SimulateSteps
from simulation_interfaces.msg import (
    Bounds,
    EntityCategory,
    EntityInfo,
    EntityState,
    Result,
    SimulationState,
    SimulatorFeatures,
)

from . import robot_spawn
from .entities import CLOTH, Entities
from .messages import checked_pose

F = SimulatorFeatures
#: what cloth_sim supports of the standard (get_simulator_features)
FEATURES = (
    F.SPAWNING,
    F.SPAWNING_ENTITIES,
    F.DELETING,
    F.ENTITY_TAGS,
    F.ENTITY_BOUNDS,
    F.ENTITY_BOUNDS_BOX,
    F.ENTITY_CATEGORIES,
    F.SPAWNING_RESOURCE_STRING,
    F.ENTITY_STATE_GETTING,
    F.ENTITY_STATE_SETTING,
    F.ENTITY_INFO_GETTING,
    F.ENTITY_INFO_SETTING,
    F.SPAWNABLES,
    F.SIMULATION_RESET,
    F.SIMULATION_RESET_TIME,
    F.SIMULATION_RESET_STATE,
    F.SIMULATION_RESET_SPAWNED,
    F.SIMULATION_STATE_GETTING,
    F.SIMULATION_STATE_SETTING,
    F.SIMULATION_STATE_PAUSE,
    F.STEP_SIMULATION_SINGLE,
    F.STEP_SIMULATION_MULTIPLE,
    F.STEP_SIMULATION_ACTION,
)
#: the services of the standard cloth_sim does not support (a cloth simulator has no worlds or
#: named poses): they answer FEATURE_UNSUPPORTED
UNSUPPORTED = {
    "get_named_poses": srv.GetNamedPoses,
    "get_named_pose_bounds": srv.GetNamedPoseBounds,
    "load_world": srv.LoadWorld,
    "unload_world": srv.UnloadWorld,
    "get_current_world": srv.GetCurrentWorld,
    "get_available_worlds": srv.GetAvailableWorlds,
}
#: the standard's reset scopes cloth_sim takes
SCOPE_ALL = srv.ResetSimulation.Request.SCOPE_ALL
#: spawn_entity's URI scheme: ``cloth_sim://<shape>?<field>=<value>&…`` (a vector as ``x,y,z``)
SCHEME = "cloth_sim"
#: what each shape needs besides its pose (initial_pose places it), with the defaults used when
#: a URI or resource does not give them
SPAWN_DEFAULTS = {
    "plane": {"normal": [0.0, 0.0, 1.0]},
    "sphere": {"center": [0.0, 0.0, 0.0]},
    "box": {"center": [0.0, 0.0, 0.0]},
    "capsule": {},
}
SPAWNABLES = {
    "sphere": "cloth_sim://sphere?radius=0.1&friction=0.3",
    "box": "cloth_sim://box?half_extents=0.2,0.2,0.02&friction=0.5",
    "capsule": "cloth_sim://capsule?a=0,0,-0.1&b=0,0,0.1&radius=0.02",
    "plane": "cloth_sim://plane?normal=0,0,1&friction=0.5",
}


def result(code: int = Result.RESULT_OK, message: str = "") -> Result:
    return Result(result=code, error_message=message)


class SimulationInterfaces:
    """Creates the standard's services and action on ``node``, over its ``session``: pause, reset
    and step through ``control``, poses and twists through ``manipulation``, messages stamped by
    ``stamp``. The ticker calls :meth:`tick` from each tick while paused, so a
    ``simulate_steps`` goal steps within the tick's budget and reports feedback."""

    def __init__(self, node, session, control, manipulation, stamp):
        self.node, self.session, self.control, self.manipulation = (
            node,
            session,
            control,
            manipulation,
        )
        self.stamp = stamp  # the node's stamp for its messages
        self.entities = Entities(session, manipulation)
        #: the colliders spawned through spawn_entity: ``{name: (position, orientation) at spawn}``
        #: (reset with SCOPE_SPAWNED removes them; SCOPE_STATE alone puts them back there)
        self.spawned: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        #: per shape, the serial number of the next generated name (never one used before)
        self._serials: dict[str, itertools.count] = {}
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
            "set_entity_info": (srv.SetEntityInfo, self.set_entity_info),
            "spawn_entity": (srv.SpawnEntity, self.spawn_entity),
            "spawn_entities": (srv.SpawnEntities, self.spawn_entities),
            "delete_entity": (srv.DeleteEntity, self.delete_entity),
            "get_spawnables": (srv.GetSpawnables, self.get_spawnables),
        }
        for name, (kind, handler) in handlers.items():
            node.create_service(kind, f"~/{name}", handler)
        for name, kind in UNSUPPORTED.items():
            node.create_service(kind, f"~/{name}", self._unsupported(name))
        self.action = ActionServer(
            node,
            SimulateSteps,
            "~/simulate_steps",
            self._execute,
            goal_callback=lambda goal: GoalResponse.ACCEPT,
            cancel_callback=lambda handle: CancelResponse.ACCEPT,
        )

    def destroy(self) -> None:
        """Destroy the action server (:meth:`rclpy.node.Node.destroy_node` does not: a node left
        with one stays in the graph, holding its action's topics, until the process ends)."""
        self.action.destroy()

    def restarted(self) -> None:
        """The simulation is at its scene's start (a new scene, ``~/reset``): nothing spawned,
        nothing set by set_entity_info."""
        self.spawned.clear()
        self.entities.forget()

    # ------------------------------------------------------------------ features and state
    def get_simulator_features(self, request, response):
        response.features.features = sorted(FEATURES)
        response.features.spawn_formats = ["cloth_sim_collider"]
        response.features.custom_info = (
            "cloth_sim: a mass-spring cloth; entities are 'cloth', "
            "'collider/<name>' and 'gripper/<name>' (a collider or "
            "gripper also by its own name); spawn_entity takes a "
            "collider: uri cloth_sim://<plane|sphere|box|capsule>?"
            "<field>=<value>&… or resource_string, a scene's collider "
            "mapping in YAML; initial_pose places it. No worlds, no "
            "named poses, no rigid-body dynamics: colliders are "
            "kinematic"
        )
        return response

    def state(self) -> int:
        if self.session.stopped:
            return SimulationState.STATE_STOPPED
        return (
            SimulationState.STATE_PAUSED if self.session.paused else SimulationState.STATE_PLAYING
        )

    def get_simulation_state(self, request, response):
        response.state.state = self.state()
        response.result = result()
        return response

    def set_simulation_state(self, request, response):
        S, R = SimulationState, srv.SetSimulationState.Response
        target, now = request.state.state, self.state()
        names = {
            S.STATE_STOPPED: "STATE_STOPPED",
            S.STATE_PLAYING: "STATE_PLAYING",
            S.STATE_PAUSED: "STATE_PAUSED",
            S.STATE_QUITTING: "STATE_QUITTING",
        }
        if target == now:
            response.result = result(R.ALREADY_IN_TARGET_STATE, f"already {names[target]}")
        elif target == S.STATE_PLAYING:
            self.session.stopped = False
            self.control.set_paused(False)
            response.result = result()
        elif target == S.STATE_PAUSED:
            if now == S.STATE_STOPPED:
                response.result = result(
                    R.INCORRECT_TRANSITION,
                    "pausing a stopped simulation: play it or step it first",
                )
            else:
                self.control.set_paused(True)
                response.result = result()
        elif target == S.STATE_STOPPED:
            self._reset_state()
            self.control.set_paused(True)
            self.session.stopped = True
            response.result = result()
        elif target == S.STATE_QUITTING:
            response.result = result(
                Result.RESULT_FEATURE_UNSUPPORTED,
                "cloth_sim does not quit through this service: stop its process "
                "(SIGINT, as ros2 launch does)",
            )
        elif target in (S.STATE_NO_WORLD, S.STATE_LOADING_WORLD):
            response.result = result(
                Result.RESULT_FEATURE_UNSUPPORTED,
                f"state.state = {target}: cloth_sim has no worlds to unload or "
                f"load (its scene is a node parameter)",
            )
        else:
            response.result = result(
                Result.RESULT_OPERATION_FAILED,
                f"state.state = {target}: not a simulation state; expected "
                f"{', '.join(f'{v} ({n})' for v, n in sorted(names.items()))}",
            )
        return response

    def _reset_state(self, spawned: dict | None = None) -> None:
        """The scene's state again (the node's reset), keeping the spawned colliders at their
        spawn poses unless ``spawned`` says which; what set_entity_info set of the scene's own
        entities is forgotten (a spawned collider that stays keeps it)."""
        kept = self.control.reset_simulation(
            keep_paused=True, spawned=self.spawned if spawned is None else spawned
        )
        self.spawned = {n: pose for n, pose in self.spawned.items() if n in kept}
        self.entities.forget(keep={f"collider/{n}" for n in self.spawned})

    def reset_simulation(self, request, response):
        R = srv.ResetSimulation.Request
        scope = R.SCOPE_ALL if request.scope == R.SCOPE_DEFAULT else request.scope
        known = R.SCOPE_TIME | R.SCOPE_STATE | R.SCOPE_SPAWNED
        if scope != SCOPE_ALL and scope & ~known:
            response.result = result(
                Result.RESULT_FEATURE_UNSUPPORTED,
                f"scope {request.scope}: cloth_sim resets SCOPE_DEFAULT, "
                f"SCOPE_ALL and any of SCOPE_TIME, SCOPE_STATE, SCOPE_SPAWNED",
            )
            return response
        despawn = bool(scope & R.SCOPE_SPAWNED)
        sim = self.session.sim
        if scope & R.SCOPE_STATE:
            t = sim.time
            self._reset_state(spawned={} if despawn else None)
            if not scope & R.SCOPE_TIME:
                sim.set_time(t)
        else:
            if despawn:
                for name in sorted(self.spawned):
                    self._remove_collider(name)
            if scope & R.SCOPE_TIME:
                sim.set_time(0.0)
        response.result = result()
        return response

    # ------------------------------------------------------------------ stepping
    def step_simulation(self, request, response):
        if self.state() == SimulationState.STATE_PLAYING:
            response.result = result(
                Result.RESULT_OPERATION_FAILED,
                "step_simulation runs only while paused or stopped: set the "
                "simulation state to STATE_PAUSED first",
            )
            return response
        ok, message = self.control.step_paused(int(request.steps))
        if ok:
            self.session.stopped = False
        response.result = result(
            Result.RESULT_OK if ok else Result.RESULT_OPERATION_FAILED, message
        )
        return response

    async def _execute(self, handle):
        steps = int(handle.request.steps)
        out = SimulateSteps.Result()
        if self.state() == SimulationState.STATE_PLAYING:
            handle.abort()
            out.result = result(
                Result.RESULT_OPERATION_FAILED, "simulate_steps runs only while paused or stopped"
            )
            return out
        if self._goal is not None:
            handle.abort()
            out.result = result(
                Result.RESULT_INCORRECT_STATE, "another simulate_steps goal is running"
            )
            return out
        done = Future()
        self._goal = [handle, steps, 0, done]
        self.session.stopped = False
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
            out.result = result(
                Result.RESULT_OPERATION_FAILED,
                f"canceled after {completed} of {completed + remaining} steps",
            )
            self._finish(out)
            return 0, 0.0, 0.0
        steps, wall, longest, message = self.control.step_within(remaining, t0, budget)
        if steps is None:  # it diverged: the node went back and paused (its message says how)
            handle.abort()
            out.result = result(Result.RESULT_OPERATION_FAILED, message)
            self._finish(out)
            return 0, 0.0, 0.0
        remaining, completed = remaining - steps, completed + steps
        self._goal[1:3] = [remaining, completed]
        handle.publish_feedback(
            SimulateSteps.Feedback(completed_steps=completed, remaining_steps=remaining)
        )
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
    def _named(self, name: str, response) -> str | None:
        """The full name ``name`` stands for; else ``None``, with NOT_FOUND in ``response``."""
        full = self.entities.resolve(name)
        if full is None:
            response.result = self.entities.unknown(name)
        return full

    def get_entities(self, request, response):
        names, response.result = self.entities.matching(request.filters)
        response.entities = names or []
        return response

    def get_entities_states(self, request, response):
        names, response.result = self.entities.matching(request.filters)
        response.entities = names or []
        response.states = [self._state(n) for n in response.entities]
        return response

    def _state(self, name: str) -> EntityState:
        sim = self.session.sim
        state = EntityState()
        state.header.frame_id = self.session.cfg["frame_id"]
        state.header.stamp = self.stamp()
        if name == CLOTH:  # its frame: the node's frame_id; its twist: the centre of mass's
            m = sim.model.masses
            v = (m @ sim.velocities) / m.sum()
            state.pose.orientation.w = 1.0
            state.twist.linear = _vec(v)
            return state
        kind, _, key = name.partition("/")
        if kind == "collider":
            c = self.entities.collider(key)
            p, q = c.position, c.orientation
        elif kind == "robot":  # a link's pose, or the robot's root link's
            robot, _, link = key.partition("/")
            p, q = sim.link_pose(robot, link or sim.robots[robot].root)
        else:
            p, q = sim.gripper_pose(key)
        v, w = self.manipulation.twist(kind, key)
        state.twist.linear = _vec(v)
        state.twist.angular = _vec(w)
        state.pose.position.x, state.pose.position.y, state.pose.position.z = (float(a) for a in p)
        (
            state.pose.orientation.w,
            state.pose.orientation.x,
            state.pose.orientation.y,
            state.pose.orientation.z,
        ) = (float(a) for a in q)
        return state

    def get_entity_state(self, request, response):
        name = self._named(request.entity, response)
        if name is not None:
            response.state = self._state(name)
            response.result = result()
        return response

    def set_entity_state(self, request, response):
        """The pose now (a teleport), then the twist it moves at; refused for the cloth, and a
        twist or acceleration for a static object."""
        name = self._named(request.entity, response)
        if name is None:
            return response
        state = request.state
        if name == CLOTH:
            response.result = result(
                Result.RESULT_OPERATION_FAILED,
                "the cloth's state is its particles': move it with its grippers "
                "(gripper/<name>) or grasp it (~/grasp)",
            )
            return response
        if name.startswith("robot/"):
            response.result = result(
                Result.RESULT_OPERATION_FAILED,
                f"{name} is moved by its joints: publish them on the robot's joint states "
                f"topic (robot.joint_states_topic)",
            )
            return response
        position, orientation, problem = checked_pose(
            state.pose, state.header.frame_id, self.manipulation.pose_frames(), prefix="state."
        )
        t, a = state.twist, state.acceleration
        linear = np.array([t.linear.x, t.linear.y, t.linear.z])
        angular = np.array([t.angular.x, t.angular.y, t.angular.z])
        if problem is None and not (np.all(np.isfinite(linear)) and np.all(np.isfinite(angular))):
            problem = (
                f"state.twist = {linear.tolist()}, {angular.tolist()}: expected finite "
                f"linear and angular velocities"
            )
        if problem:
            response.result = result(srv.SetEntityState.Response.INVALID_POSE, problem)
            return response
        moving = bool(np.any(linear) or np.any(angular))
        accel = any((a.linear.x, a.linear.y, a.linear.z, a.angular.x, a.angular.y, a.angular.z))
        if (moving or accel) and self.entities.is_static(name):
            what = "twist" if moving else "acceleration"
            response.result = result(
                Result.RESULT_OPERATION_FAILED,
                f"state.{what}: {name} is a STATIC_OBJECT, which the standard "
                f"does not let move; set_entity_info with category "
                f"DYNAMIC_OBJECT ({EntityCategory.CATEGORY_DYNAMIC_OBJECT}) "
                f"makes it a kinematic obstacle that moves at a twist; nothing "
                f"was changed",
            )
            return response
        kind, _, key = name.partition("/")
        sim = self.session.sim
        self.manipulation.forget_pose_target(
            kind, key
        )  # a pose streamed before this one is overtaken
        if kind == "collider":
            index = next(i for i, c in enumerate(sim.colliders) if c.name == key)
            sim.set_collider_pose(index, position, orientation, teleport=True)
        else:
            sim.set_gripper_pose(key, position, orientation, teleport=True)
        self.manipulation.set_twist(
            kind, key, linear, angular
        )  # kinematic: it keeps this velocity
        response.result = result(
            Result.RESULT_OK,
            ""
            if not accel
            else "state.acceleration ignored: kinematic entities move at their twist",
        )
        return response

    def spawn_entity(self, request, response):
        """A collider from ``uri`` (``cloth_sim://<shape>?…``) or ``resource_string`` (YAML: a
        scene's collider mapping), placed at ``initial_pose``."""
        response.result, response.entity_name = self._spawn(request)
        return response

    def spawn_entities(self, request, response):
        """Each request as ``spawn_entity`` would take it, in order; ENTITIES_SPAWN_FAILED when any
        failed (the others are spawned all the same, as the standard says)."""
        from simulation_interfaces.msg import SpawnResult

        for one in request.spawn_requests:
            r, name = self._spawn(one, one.entity_resource)
            response.results.append(SpawnResult(result=r, entity_name=name))
        failed = [i for i, r in enumerate(response.results) if r.result.result != Result.RESULT_OK]
        response.result = (
            result()
            if not failed
            else result(
                srv.SpawnEntities.Response.ENTITIES_SPAWN_FAILED,
                f"spawn_requests {failed} failed (see results)",
            )
        )
        return response

    def _spawn(self, request, resource=None) -> tuple[Result, str]:
        """``(result, entity name)`` of spawning what ``request`` describes (its ``uri`` and
        ``resource_string``, or those of ``resource``): a URDF robot (:func:`.robot_spawn.spawn`)
        or a collider."""
        resource = resource or request
        if robot_spawn.is_urdf(resource):
            return robot_spawn.spawn(self, request, resource)
        code, message, collider = self._collider_from(request, resource)
        if collider is None:
            return result(code, message), ""
        self.session.sim.add_collider(collider)
        self.spawned[collider.name] = (collider.position.copy(), collider.orientation.copy())
        self.manipulation.colliders_changed()
        name = f"collider/{collider.name}"
        return result(
            Result.RESULT_OK,
            f"spawned {type(collider).__name__.lower()} {name} (also "
            f"addressed as {collider.name!r})",
        ), name

    def _collider_from(self, request, resource):
        """``(code, message, collider)``: the collider a spawn request describes, or the standard's
        code and the reason (collider ``None``)."""
        import yaml

        from ..contact.colliders import KINDS
        from ..scene import GRIPPER_NAME, SceneError, SceneValidator

        R = srv.SpawnEntity.Response
        if not resource.uri and not resource.resource_string:
            return (
                R.NO_RESOURCE,
                "give uri (cloth_sim://<shape>?…) or resource_string (YAML)",
                None,
            )
        if request.entity_namespace:
            return (
                Result.RESULT_FEATURE_UNSUPPORTED,
                f"entity_namespace = "
                f"{request.entity_namespace!r}: cloth_sim's colliders have no ROS interfaces "
                f"of their own to put under a namespace; leave it empty",
                None,
            )
        if resource.uri:
            spec = _parse_uri(resource.uri)
            if isinstance(spec, str):
                return R.UNSUPPORTED_FORMAT, spec, None
        else:
            try:
                spec = yaml.safe_load(resource.resource_string)
            except yaml.YAMLError as e:
                return R.RESOURCE_PARSE_ERROR, f"resource_string is not YAML ({e})", None
            if not isinstance(spec, dict) or spec.get("type") not in SPAWN_DEFAULTS:
                return (
                    R.UNSUPPORTED_FORMAT,
                    "resource_string must be a mapping with type: plane, "
                    "sphere, box or capsule, and that shape's fields",
                    None,
                )
        kind = spec["type"]
        spec = {**SPAWN_DEFAULTS[kind], **spec}
        # the name: the request's, else the resource's own (as the standard says)
        name = request.name or (spec.get("name") if isinstance(spec.get("name"), str) else "")
        if name and not GRIPPER_NAME.fullmatch(name):  # the rule every entity name follows
            return (
                R.NAME_INVALID,
                f"name = {name!r}: expected ASCII letters, digits and _ (not "
                f"starting with a digit, at most 64): it names the collider's topic and frame",
                None,
            )
        try:
            kind, kw = SceneValidator("spawn_entity").collider(0, {**spec, "name": name or kind})
        except SceneError as e:
            return R.RESOURCE_PARSE_ERROR, str(e).replace("colliders[0].", ""), None
        position, orientation, problem = checked_pose(
            request.initial_pose.pose,
            request.initial_pose.header.frame_id,
            self.manipulation.pose_frames(),
            prefix="initial_pose.",
        )
        if problem:
            return R.INVALID_POSE, problem, None
        if not name and not request.allow_renaming:
            return (
                R.NAME_INVALID,
                "name is empty (and the resource names none) while "
                "allow_renaming is false: give a name, or allow_renaming: true for a generated "
                "one",
                None,
            )
        taken = self.entities.taken()
        if name in taken and not request.allow_renaming:
            return (
                R.NAME_NOT_UNIQUE,
                f"an entity named {name!r} exists (allow_renaming: false)",
                None,
            )
        if not name or name in taken:  # a name never given before: <name or shape>_<k>
            serial = self._serials.setdefault(name or kind, itertools.count(1))
            name = next(c for c in (f"{name or kind}_{k}" for k in serial) if c not in taken)
        kw["name"] = name
        collider = KINDS[kind](**kw)
        # the pose: a sphere's or box's centre, a capsule's midpoint, a point on a plane (the
        # identity orientation keeps a plane's normal and a capsule's segment as built)
        collider.set_pose(position, orientation)
        return Result.RESULT_OK, "", collider

    def delete_entity(self, request, response):
        name = self._named(request.entity, response)
        if name is None:
            return response
        if name == CLOTH:
            response.result = result(
                Result.RESULT_OPERATION_FAILED,
                "the cloth cannot be deleted (a scene change replaces it)",
            )
        elif name.startswith("gripper/"):
            self.manipulation.release_gripper(name.partition("/")[2])
            response.result = result(Result.RESULT_OK, f"{name} released the cloth")
        elif name.startswith("robot/"):
            robot, _, link = name.partition("/")[2].partition("/")
            if link:
                response.result = result(
                    Result.RESULT_OPERATION_FAILED,
                    f"{name} is a link of robot/{robot}: delete the robot",
                )
            else:
                self.session.sim.remove_robot(robot)
                self.manipulation.colliders_changed()
                response.result = result()
        else:
            self._remove_collider(name.partition("/")[2])
            response.result = result()
        return response

    def _remove_collider(self, name: str) -> None:
        sim = self.session.sim
        index = next((i for i, c in enumerate(sim.colliders) if c.name == name), None)
        if index is not None:
            sim.remove_collider(index)
            self.manipulation.set_twist("collider", name, 0, 0)
            self.manipulation.colliders_changed()
        self.spawned.pop(name, None)

    def get_spawnables(self, request, response):
        from simulation_interfaces.msg import Spawnable

        response.spawnables = [
            Spawnable(
                uri=uri,
                description=f"a {kind} collider (fields as in a "
                f"scene file; initial_pose places it)",
            )
            for kind, uri in SPAWNABLES.items()
        ]
        # sources the simulator does not know are named, and do not hinder success (the standard)
        response.result = result(
            Result.RESULT_OK,
            ""
            if not request.sources
            else (
                f"sources not recognised: {', '.join(request.sources)} (cloth_sim's spawnables "
                "are its "
                f"collider shapes)"
            ),
        )
        return response

    def get_entity_bounds(self, request, response):
        name = self._named(request.entity, response)
        if name is None:
            return response
        box = self.entities.box(name)
        b = Bounds()
        if box is None:
            b.type = Bounds.TYPE_EMPTY  # an infinite plane: unbounded
        else:
            b.type = Bounds.TYPE_BOX
            b.points = [_vec(box[0]), _vec(box[1])]
        response.bounds = b
        response.result = result()
        return response

    def get_entity_info(self, request, response):
        name = self._named(request.entity, response)
        if name is not None:
            category, description, tags = self.entities.info(name)
            response.info = EntityInfo(
                category=EntityCategory(category=category),
                description=description,
                tags=list(tags),
            )
            response.result = result()
        return response

    def set_entity_info(self, request, response):
        name = self._named(request.entity, response)
        if name is not None:
            info = request.info
            response.result = self.entities.set_info(
                name, info.category.category, info.description, info.tags
            )
        return response

    @staticmethod
    def _unsupported(name: str):
        def handler(request, response):
            response.result = result(
                Result.RESULT_FEATURE_UNSUPPORTED,
                f"{name} is not supported by cloth_sim (get_simulator_features lists what is)",
            )
            return response

        return handler


def _vec(a) -> Vector3:
    return Vector3(x=float(a[0]), y=float(a[1]), z=float(a[2]))


def _parse_uri(uri: str):
    """``{type, fields…}`` of a ``cloth_sim://<shape>?<field>=<value>&…`` URI (numbers, and vectors
    as ``x,y,z``), or the reason it is not one (a string)."""
    from urllib.parse import parse_qsl

    # (by hand: an underscore is no URI scheme character for urllib)
    shape, _, query = uri[len(SCHEME) + 3 :].partition("?")
    if not uri.startswith(f"{SCHEME}://") or shape not in SPAWN_DEFAULTS:
        return (
            f"uri = {uri!r}: expected {SCHEME}://<shape>?<field>=<value>&… with shape one of "
            f"{', '.join(SPAWN_DEFAULTS)} (get_spawnables lists examples)"
        )
    spec = {"type": shape}
    for key, value in parse_qsl(query, keep_blank_values=True):
        try:
            numbers = [float(v) for v in value.split(",")]
        except ValueError:
            return f"uri field {key} = {value!r}: expected a number or numbers separated by commas"
        spec[key] = numbers[0] if len(numbers) == 1 else numbers
    return spec
