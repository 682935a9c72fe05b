"""The entity services of the ROS simulation standard: ``get_entities``,
``get_entities_states``, ``get_entity_state``, ``set_entity_state``, ``delete_entity``,
``get_entity_bounds``, ``get_entity_info``, ``set_entity_info``.

Entities, their names, categories and bounds: :mod:`cloth_sim.ros.entities`. A client may address
an entity by the name it gave at spawn or by the full name the response returned. States are in the
node's ``frame_id``; a pose may also be given in its ``world_frame_id`` (``/tf_static`` makes them
one frame) or with an empty frame (the standard's default).

``set_entity_state`` sets a state, as the standard says: a pose is a teleport (the entity is there
at once and at rest; the cloth is not dragged, and what a collider now overlaps is pushed out at
the next step), a twist is what the entity then moves at — refused for a static object (a collider
unless ``set_entity_info`` made it, say, a DYNAMIC_OBJECT). Streaming poses on
``~/colliders/<name>/pose`` keeps its swept motion (friction drags what rests on the collider).
"""

from __future__ import annotations

import numpy as np
from simulation_interfaces import srv
from simulation_interfaces.msg import Bounds, EntityCategory, EntityInfo, EntityState, Result

from .entities import CLOTH, Entities
from .messages import checked_pose, result, vector
from .spawning import Spawner


class EntityServices:
    """The entity services over the node's ``session`` (its simulator), ``manipulation`` (pose
    frames and twists), ``entities`` (names, categories, bounds) and ``spawner`` (a deleted
    spawned collider is forgotten there); states stamped by ``stamp``."""

    def __init__(self, session, manipulation, entities: Entities, spawner: Spawner, stamp):
        self.session, self.manipulation, self.entities = session, manipulation, entities
        self.spawner = spawner
        self.stamp = stamp  # the node's stamp for its messages

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
            state.twist.linear = vector(v)
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
        state.twist.linear = vector(v)
        state.twist.angular = vector(w)
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
            self.spawner.remove_collider(name.partition("/")[2])
            response.result = result()
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
            b.points = [vector(box[0]), vector(box[1])]
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
