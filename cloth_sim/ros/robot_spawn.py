"""``spawn_entity`` of a URDF robot, as Gazebo's ``create`` takes one: the URDF as the request's
``resource_string``, or its ``uri`` (``file://…``, ``package://…`` looked up in the ament index
and ``ROS_PACKAGE_PATH``, or a path). The robot is placed at ``initial_pose`` (its root link's
pose) with its joints at 0 and is the entity ``robot/<name>``; its links are
``robot/<name>/<link>`` (:mod:`.entities`)."""

from __future__ import annotations

from urllib.parse import unquote, urlparse

from simulation_interfaces import srv
from simulation_interfaces.msg import Result

from ..robot import Robot, resources
from ..scene import GRIPPER_NAME as NAME  # the rule every entity name follows
from .messages import checked_pose


def is_urdf(resource) -> bool:
    """Whether a spawn request's resource is a URDF (XML text, or a ``.urdf`` URI)."""
    if resource.resource_string and resource.resource_string.lstrip().startswith("<"):
        return True
    uri = resource.uri or ""
    return uri.lower().endswith((".urdf", ".urdf.xml"))


def _load(resource) -> Robot:
    if resource.resource_string:
        return Robot.from_urdf(resource.resource_string)
    uri = resource.uri
    if uri.startswith("package://"):
        return Robot.from_urdf(resources.resolve(uri, None, resources.package_roots()))
    if uri.startswith("file://"):
        return Robot.from_urdf(unquote(urlparse(uri).path))
    return Robot.from_urdf(uri)


def spawn(interfaces, request, resource) -> tuple[Result, str]:
    """``(result, entity name)``: the robot ``resource`` describes put in the scene of
    ``interfaces`` (the node's :class:`~cloth_sim.ros.spawning.Spawner`)."""
    R = srv.SpawnEntity.Response
    if request.entity_namespace:
        return Result(
            result=Result.RESULT_FEATURE_UNSUPPORTED,
            error_message=(
                f"entity_namespace = {request.entity_namespace!r}: a robot in cloth_sim has no "
                f"ROS interfaces of its own to put under a namespace; leave it empty"
            ),
        ), ""
    try:
        robot = _load(resource)
    except ValueError as e:
        return Result(result=R.RESOURCE_PARSE_ERROR, error_message=str(e)), ""
    position, orientation, problem = checked_pose(
        request.initial_pose.pose,
        request.initial_pose.header.frame_id,
        interfaces.manipulation.pose_frames(),
        prefix="initial_pose.",
    )
    if problem:
        return Result(result=R.INVALID_POSE, error_message=problem), ""
    name = request.name or robot.name
    if not NAME.fullmatch(name):
        return Result(
            result=R.NAME_INVALID,
            error_message=(
                f"name = {name!r}: expected ASCII letters, digits and _ (not starting with a "
                f"digit, at most 64)"
            ),
        ), ""
    taken = interfaces.entities.taken() | set(interfaces.session.sim.robots)
    if name in taken:
        if not request.allow_renaming:
            return Result(
                result=R.NAME_NOT_UNIQUE,
                error_message=f"an entity named {name!r} exists (allow_renaming: false)",
            ), ""
        name = next(f"{name}_{k}" for k in range(1, 10_000) if f"{name}_{k}" not in taken)
    sim = interfaces.session.sim
    try:
        sim.add_robot(robot, name=name, position=position, orientation=orientation)
    except ValueError as e:  # a device without robots (cuda): nothing spawned
        return Result(result=Result.RESULT_FEATURE_UNSUPPORTED, error_message=str(e)), ""
    interfaces.manipulation.colliders_changed()
    return Result(
        result=Result.RESULT_OK,
        error_message=(
            f"spawned robot/{name} from the URDF {robot.name!r}: {len(robot.joint_names)} "
            f"joints, {len(robot.link_names)} links with collisions"
        ),
    ), f"robot/{name}"
