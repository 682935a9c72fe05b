"""The ROS simulation standard (``simulation_interfaces``, Jazzy) over the node.

Gazebo, Isaac Sim and O3DE answer the same services; cloth_sim answers them under its node's
namespace with the standard's snake_case names (``/cloth_sim/step_simulation``, …), as Gazebo does
under ``/gzserver/``. Each service is one small handler here; they reach the simulation through the
node's own operations (pause, reset, step, poses), so the package's services (``~/pause``,
``~/reset``, ``~/step``) and these stay one behaviour. ``get_simulator_features`` says what is
supported (:data:`FEATURES`); every other service of the standard exists too and answers
``RESULT_FEATURE_UNSUPPORTED`` with a message, never a time-out.

Entities: ``cloth`` (the cloth itself, CATEGORY_OBJECT), ``collider/<name>`` (the scene's
colliders, CATEGORY_STATIC_OBJECT: kinematic, moved by pose) and ``gripper/<name>`` (each gripper
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
FEATURES = (F.ENTITY_STATE_GETTING, F.ENTITY_STATE_SETTING, F.ENTITY_BOUNDS, F.ENTITY_CATEGORIES,
            F.ENTITY_INFO_GETTING, F.SIMULATION_RESET, F.SIMULATION_RESET_TIME,
            F.SIMULATION_RESET_STATE, F.SIMULATION_STATE_GETTING, F.SIMULATION_STATE_SETTING,
            F.SIMULATION_STATE_PAUSE, F.STEP_SIMULATION_SINGLE, F.STEP_SIMULATION_MULTIPLE,
            F.STEP_SIMULATION_ACTION)
#: the services of the standard cloth_sim does not support (yet): they answer FEATURE_UNSUPPORTED
UNSUPPORTED = {
    "spawn_entity": srv.SpawnEntity, "spawn_entities": srv.SpawnEntities,
    "delete_entity": srv.DeleteEntity, "get_spawnables": srv.GetSpawnables,
    "set_entity_info": srv.SetEntityInfo, "get_named_poses": srv.GetNamedPoses,
    "get_named_pose_bounds": srv.GetNamedPoseBounds, "load_world": srv.LoadWorld,
    "unload_world": srv.UnloadWorld, "get_current_world": srv.GetCurrentWorld,
    "get_available_worlds": srv.GetAvailableWorlds,
}
#: the standard's reset scopes cloth_sim takes
SCOPES = {srv.ResetSimulation.Request.SCOPE_DEFAULT, srv.ResetSimulation.Request.SCOPE_ALL,
          srv.ResetSimulation.Request.SCOPE_TIME, srv.ResetSimulation.Request.SCOPE_STATE,
          srv.ResetSimulation.Request.SCOPE_TIME | srv.ResetSimulation.Request.SCOPE_STATE}
CLOTH = "cloth"


def result(code: int = Result.RESULT_OK, message: str = "") -> Result:
    return Result(result=code, error_message=message)


class SimulationInterfaces:
    """Creates the standard's services and action on ``node`` (a :class:`~cloth_sim.ros.node.
    ClothSimNode`); the node calls :meth:`tick` from each tick while paused, so a
    ``simulate_steps`` goal steps within the tick's budget and reports feedback."""

    def __init__(self, node):
        self.node = node
        self.stopped = False
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
        response.features.spawn_formats = []
        response.features.custom_info = ("cloth_sim: a mass-spring cloth; entities are 'cloth', "
                                         "'collider/<name>' and 'gripper/<name>'")
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
        scope = request.scope
        if scope not in SCOPES:
            response.result = result(Result.RESULT_FEATURE_UNSUPPORTED,
                                     f"scope {scope}: cloth_sim resets SCOPE_DEFAULT, SCOPE_ALL, "
                                     f"SCOPE_TIME, SCOPE_STATE (it spawns nothing to despawn)")
            return response
        sim = self.node.sim
        if scope == R.SCOPE_TIME:
            sim.set_time(0.0)
        elif scope == R.SCOPE_STATE:
            t = sim.time
            self.node.reset_simulation(keep_paused=True)
            sim.set_time(t)
        else:
            self.node.reset_simulation(keep_paused=True)
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
            c = next(c for c in sim.colliders if c.name == key)
            p, q = c.position, c.orientation
        else:
            p, q = sim.gripper_pose(key)
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
        twist = state.twist
        if problem is None and any((twist.linear.x, twist.linear.y, twist.linear.z,
                                    twist.angular.x, twist.angular.y, twist.angular.z)):
            problem = ("state.twist: cloth_sim's colliders and grippers are kinematic, moved by pose; "
                       "give a zero twist (the pose is reached over the next step)")
        if problem:
            response.result = result(srv.SetEntityState.Response.INVALID_POSE, problem)
            return response
        kind, _, key = name.partition("/")
        sim = self.node.sim
        if kind == "collider":
            index = next(i for i, c in enumerate(sim.colliders) if c.name == key)
            sim.set_collider_pose(index, position, orientation)
        else:
            sim.set_gripper_pose(key, position, orientation)
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
            c = next(c for c in sim.colliders if c.name == key)
            pts = collider_extent(c)
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
