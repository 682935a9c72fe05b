"""The ROS simulation standard (``simulation_interfaces``, Jazzy) over the node.

Gazebo, Isaac Sim and O3DE answer the same services; cloth_sim answers them under its node's
namespace with the standard's snake_case names (``/cloth_sim/step_simulation``, …), as Gazebo does
under ``/gzserver/``. Each service is one small handler here; they reach the simulation through the
node's own operations (pause, reset, step, poses), so the package's services (``~/pause``,
``~/reset``, ``~/step``) and these stay one behaviour. ``get_simulator_features`` says what is
supported (:data:`FEATURES`); every other service of the standard exists too and answers
``RESULT_FEATURE_UNSUPPORTED`` with a message, never a time-out.

The entity services are :mod:`.entity_services`', spawning :mod:`.spawning`'; this module wires
every service and answers the simulation's state, reset and stepping.

Simulation states: PLAYING (ticking), PAUSED (``~/pause``), STOPPED (reset to the start and paused;
from there PLAYING or a step goes on, PAUSED is an incorrect transition, as the standard defines).
``step_simulation`` and the ``simulate_steps`` action step only while paused or stopped.
``reset_simulation`` returns the scene: the cloth, its grippers, its colliders where it puts them
(moved, deleted or set moving since), without twists; SCOPE_SPAWNED removes the spawned colliders,
SCOPE_STATE alone puts them back where they were spawned.
"""

from __future__ import annotations

from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.task import Future
from simulation_interfaces import srv
from simulation_interfaces.action import SimulateSteps
from simulation_interfaces.msg import Result, SimulationState, SimulatorFeatures

from .entities import Entities
from .entity_services import EntityServices
from .messages import result
from .spawning import Spawner

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


class SimulationInterfaces:
    """Creates the standard's services and action on ``node``, over its ``session``: pause, reset
    and step through ``control``, poses and twists through ``manipulation``, messages stamped by
    ``stamp``. The ticker calls :meth:`tick` from each tick while paused, so a
    ``simulate_steps`` goal steps within the tick's budget and reports feedback."""

    def __init__(self, node, session, control, manipulation, stamp):
        self.node, self.session, self.control = node, session, control
        entities = Entities(session, manipulation)
        self.entities = entities
        self.spawner = Spawner(session, manipulation, entities)
        entity = EntityServices(session, manipulation, entities, self.spawner, stamp)
        self._goal = None  # (goal handle, remaining steps, completed, future) of simulate_steps
        handlers = {
            "get_simulator_features": (srv.GetSimulatorFeatures, self.get_simulator_features),
            "get_simulation_state": (srv.GetSimulationState, self.get_simulation_state),
            "set_simulation_state": (srv.SetSimulationState, self.set_simulation_state),
            "reset_simulation": (srv.ResetSimulation, self.reset_simulation),
            "step_simulation": (srv.StepSimulation, self.step_simulation),
            "get_entities": (srv.GetEntities, entity.get_entities),
            "get_entities_states": (srv.GetEntitiesStates, entity.get_entities_states),
            "get_entity_state": (srv.GetEntityState, entity.get_entity_state),
            "set_entity_state": (srv.SetEntityState, entity.set_entity_state),
            "get_entity_bounds": (srv.GetEntityBounds, entity.get_entity_bounds),
            "get_entity_info": (srv.GetEntityInfo, entity.get_entity_info),
            "set_entity_info": (srv.SetEntityInfo, entity.set_entity_info),
            "spawn_entity": (srv.SpawnEntity, self.spawner.spawn_entity),
            "spawn_entities": (srv.SpawnEntities, self.spawner.spawn_entities),
            "delete_entity": (srv.DeleteEntity, entity.delete_entity),
            "get_spawnables": (srv.GetSpawnables, self.spawner.get_spawnables),
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
        self.spawner.spawned.clear()
        self.entities.forget()

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
            keep_paused=True, spawned=self.spawner.spawned if spawned is None else spawned
        )
        self.spawner.spawned = {n: p for n, p in self.spawner.spawned.items() if n in kept}
        self.entities.forget(keep={f"collider/{n}" for n in self.spawner.spawned})

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
                for name in sorted(self.spawner.spawned):
                    self.spawner.remove_collider(name)
            if scope & R.SCOPE_TIME:
                sim.set_time(0.0)
        response.result = result()
        return response

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

    @staticmethod
    def _unsupported(name: str):
        def handler(request, response):
            response.result = result(
                Result.RESULT_FEATURE_UNSUPPORTED,
                f"{name} is not supported by cloth_sim (get_simulator_features lists what is)",
            )
            return response

        return handler
