"""The node's own topics and services, declared once: the node's parts create them from here
(:func:`publisher`, :func:`subscription`, :func:`service`, which refuse a message class other than
the one declared), the site's tables are generated from here, and ``test/ros`` checks a running
node's graph against it. (The ROS simulation standard's services are :mod:`.sim_interfaces`'.)

A name holding ``{name}`` is one topic per gripper or collider (``~/grippers/{name}/pose``).
Names are relative to the node (``~/``) unless absolute. Nothing here imports rclpy.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Topic:
    name: str
    #: the message type, ``package/msg/Name``
    type: str
    #: ``"out"`` the node publishes, ``"in"`` it subscribes
    direction: str
    #: the QoS history depth (keep last)
    depth: int
    what: str
    #: ``"transient local"`` for a latched topic, else volatile
    durability: str = "volatile"


@dataclass(frozen=True)
class Service:
    name: str
    #: the service type, ``package/srv/Name``
    type: str
    what: str


TOPICS = {
    "points": Topic(
        "~/points",
        "sensor_msgs/msg/PointCloud2",
        "out",
        10,
        "the cloth's particles: a grid's cloud is organised (height = rows, width = cols), a "
        "mesh's one row; float32 x y z, `is_dense`; built only when subscribed",
    ),
    "mesh": Topic(
        "~/mesh",
        "visualization_msgs/msg/Marker",
        "out",
        10,
        "TRIANGLE_LIST of the cloth for RViz; built only when subscribed",
    ),
    "colliders": Topic(
        "~/colliders",
        "visualization_msgs/msg/MarkerArray",
        "out",
        10,
        "the scene's colliders (`ns` = collider name), every tick while subscribed",
    ),
    "stats": Topic(
        "~/stats",
        "cloth_sim/msg/Stats",
        "out",
        10,
        "every tick: integrator, dt, steps, step time mean/max, tick wall time, real-time "
        "factor, sim time, kinetic/potential energy, max strain, overruns, stability margin "
        "dt/stable_dt, paused, solver iterations and residual",
    ),
    "diagnostics": Topic(
        "/diagnostics",
        "diagnostic_msgs/msg/DiagnosticArray",
        "out",
        10,
        "1 Hz, status `cloth_sim: simulation`: WARN when the real-time factor is below 95 % of "
        "`real_time_factor`, dt > 80 % of stable_dt or the energy balance fails, ERROR after a "
        "blow-up",
    ),
    "clock": Topic(
        "/clock",
        "rosgraph_msgs/msg/Clock",
        "out",
        10,
        "the simulated time, every tick, with `publish_clock` (every message is then stamped "
        "with it)",
    ),
    "tf_static": Topic(
        "/tf_static",
        "tf2_msgs/msg/TFMessage",
        "out",
        1,
        "`world_frame_id` → `frame_id`, the identity, again when either changes",
        durability="transient local",
    ),
    "tf": Topic(
        "/tf",
        "tf2_msgs/msg/TFMessage",
        "out",
        100,
        "each collider and gripper as a frame in `frame_id` (`cloth/collider/<name>`, "
        "`cloth/gripper/<name>`), every tick while subscribed",
    ),
    "camera_image": Topic(
        "~/camera/depth/image",
        "sensor_msgs/msg/Image",
        "out",
        5,
        "`32FC1` depth in metres along the optical axis, NaN where nothing is in [near, far] "
        "(REP 118); frame `<frame_id>/camera_optical`; only while `camera.enable` and "
        "subscribed, at `camera.rate`",
    ),
    "camera_info": Topic(
        "~/camera/depth/camera_info",
        "sensor_msgs/msg/CameraInfo",
        "out",
        5,
        "the pinhole intrinsics (no distortion), the image's size",
    ),
    "camera_points": Topic(
        "~/camera/points",
        "sensor_msgs/msg/PointCloud2",
        "out",
        5,
        "organised (height × width) float32 x y z in the optical frame, NaN where the image is: "
        "what `depth_image_proc` makes of the image",
    ),
    "camera_labels": Topic(
        "~/camera/labels",
        "sensor_msgs/msg/Image",
        "out",
        5,
        "ground truth per pixel, `16SC1`: −1 nothing, 0 the cloth, 1 + i collider i",
    ),
    "camera_triangles": Topic(
        "~/camera/triangles",
        "sensor_msgs/msg/Image",
        "out",
        5,
        "ground truth per pixel, `32SC1`: the cloth triangle seen (index into the mesh), −1 "
        "elsewhere",
    ),
    "collider_pose": Topic(
        "~/colliders/{name}/pose",
        "geometry_msgs/msg/PoseStamped",
        "in",
        10,
        "moves collider `<name>`: reached over the next tick's steps, so friction drags what "
        "rests on it; `frame_id` empty or the node's; a non-finite pose is logged and ignored",
    ),
    "gripper_pose": Topic(
        "~/grippers/{name}/pose",
        "geometry_msgs/msg/PoseStamped",
        "in",
        10,
        "moves gripper `<name>` (from `~/grasp` to `~/release`), reached over the next tick's "
        "steps; the same checks as a collider's pose",
    ),
    "gripper_wrench": Topic(
        "~/grippers/{name}/wrench",
        "geometry_msgs/msg/WrenchStamped",
        "out",
        10,
        "every tick: the force and torque (about the gripper's position) the cloth exerts on "
        "gripper `<name>`, world frame",
    ),
    "link_wrench": Topic(
        "~/robots/{name}/wrench",
        "geometry_msgs/msg/WrenchStamped",
        "out",
        10,
        "every tick, for each link with a collision of each robot in the scene (`<name>` = "
        "`<robot>/<link>`): the force and torque (about the link's origin) the cloth exerts on "
        "it, world frame: what a finger holding the cloth by friction feels",
    ),
    "robot_description": Topic(
        "/robot_description",
        "std_msgs/msg/String",
        "in",
        1,
        "with `robot.enable`: the robot's URDF (`robot.description_topic`); each message puts "
        "that robot in the scene, its links colliders, in place of the last; one that does not "
        "load is logged and the scene is kept",
        durability="transient local",
    ),
    "joint_states": Topic(
        "/joint_states",
        "sensor_msgs/msg/JointState",
        "in",
        10,
        "with `robot.enable` (`robot.joint_states_topic`): joint positions, reached over the next "
        "tick's steps; an unknown joint or a non-finite value is logged and the message ignored; "
        "none for 1 s WARNs on /diagnostics",
    ),
}

SERVICES = {
    "reset": Service(
        "~/reset",
        "std_srvs/srv/Trigger",
        "back to the initial shape, at rest, time 0 (parameters kept)",
    ),
    "pause": Service(
        "~/pause",
        "std_srvs/srv/SetBool",
        "`data: true` pauses, `false` resumes (also after a blow-up)",
    ),
    "step": Service(
        "~/step",
        "cloth_sim/srv/Step",
        "`steps` → `success`, `message`, `sim_time`: exactly `steps` steps while paused "
        "(refused while running; at most 100,000 a call)",
    ),
    "grasp": Service(
        "~/grasp",
        "cloth_sim/srv/Grasp",
        "`gripper`, `point`, `radius` → `success`, `message`, `count`: hold every free particle "
        "within `radius` of `point`",
    ),
    "release": Service(
        "~/release",
        "cloth_sim/srv/Release",
        "`gripper` → `success`, `message`: let go (the particles keep the gripper's velocity)",
    ),
}


def type_name(cls) -> str:
    """``package/msg/Name`` (or ``srv``) of a generated rclpy message or service class."""
    package, kind = cls.__module__.split(".")[:2]
    return f"{package}/{kind}/{cls.__name__}"


def _declared(cls, entry) -> None:
    if type_name(cls) != entry.type:
        raise TypeError(f"{entry.name}: declared {entry.type}, created with {type_name(cls)}")


def topic_name(key: str, **names) -> str:
    """:data:`TOPICS` ``[key]``'s name as created, ``names`` filling its ``{name}``."""
    return TOPICS[key].name.format(**names)


def publisher(node, key: str, cls, qos=None, **names):
    """The publisher of :data:`TOPICS` ``[key]`` (``qos``: a profile instead of its depth)."""
    _declared(cls, TOPICS[key])
    return node.create_publisher(cls, topic_name(key, **names), qos or TOPICS[key].depth)


def subscription(node, key: str, cls, callback, qos=None, topic=None, **names):
    """The subscription of :data:`TOPICS` ``[key]``; ``names`` fill its ``{name}``; ``qos`` a
    profile instead of its depth, ``topic`` another name for it (one a parameter gives)."""
    _declared(cls, TOPICS[key])
    name = topic or topic_name(key, **names)
    return node.create_subscription(cls, name, callback, qos or TOPICS[key].depth)


def service(node, key: str, cls, callback):
    """The service of :data:`SERVICES` ``[key]``."""
    s = SERVICES[key]
    _declared(cls, s)
    return node.create_service(cls, s.name, callback)
