"""What other projects' simulation_interfaces clients expect, against cloth_sim_node.

Three clients nobody here wrote, ported to rclpy against the node: their assertions' intent kept,
only the namespace (``/cloth_sim/``), the entity names and the resources changed (cloth_sim's
entities are a cloth and kinematic colliders; its spawnables are ``cloth_sim://<shape>`` URIs).

* Gazebo: gazebosim/ros_gz, ``ros_gz_sim/test/test_gz_simulation_interfaces.launch.py`` (and
  ``test_gz_simulation_interfaces_spawn_entity.cpp``) — tests ``test_gazebo_*``;
* Isaac Sim: isaac-sim/IsaacSim, ``source/extensions/isaacsim.ros2.sim_control/python/tests/
  test_sim_control_services.py`` — tests ``test_isaac_*``;
* RobotecAI/simulation_interfaces_examples, ``warehouse_simulation_script.py`` (its sequence with
  the ``gazebo`` backend's naming) — ``test_robotec_warehouse_script``.

Where a client's expectation contradicts the standard's own text (ros-simulation/
simulation_interfaces, branch jazzy, 1.5.1), the test follows the standard and says so. What a
cloth simulator does not have (a rolling rigid body, robots driven by cmd_vel, worlds) is named in
each test and in the README's feature table.

The first tests (``test_defect_*``) are the defects those clients found (issue 40), each one
reproduced on the code before the fix.
"""

import math
import signal
import time

import numpy as np
import pytest
from geometry_msgs.msg import Point, PoseStamped, Quaternion
from rclpy.action import ActionClient
from ros_helpers import end_node, next_domain, start_node
from simulation_interfaces import srv
from simulation_interfaces.action import SimulateSteps
from simulation_interfaces.msg import (
    Bounds,
    EntityCategory,
    EntityFilters,
    EntityInfo,
    EntityState,
    Resource,
    Result,
    SimulationState,
    SimulatorFeatures,
    TagsFilter,
)
from simulation_interfaces.msg import SpawnEntity as SpawnEntityMsg
from std_srvs.srv import Trigger

NS = "/cloth_sim"
S = SimulationState
R = srv.ResetSimulation.Request


def call(ros, kind, service, **fields):
    return ros.call(kind, f"{NS}/{service}", kind.Request(**fields))


def set_state(ros, state) -> Result:
    return call(ros, srv.SetSimulationState, "set_simulation_state", state=S(state=state)).result


def get_state(ros) -> int:
    return call(ros, srv.GetSimulationState, "get_simulation_state").state.state


def step(ros, n) -> Result:
    return call(ros, srv.StepSimulation, "step_simulation", steps=n).result


def pose(x=0.0, y=0.0, z=0.0, q=(1.0, 0.0, 0.0, 0.0), frame=""):
    p = PoseStamped()
    p.header.frame_id = frame
    p.pose.position = Point(x=float(x), y=float(y), z=float(z))
    p.pose.orientation = Quaternion(w=float(q[0]), x=float(q[1]), y=float(q[2]), z=float(q[3]))
    return p


def spawn(ros, name="", uri="", resource_string="", at=None, allow_renaming=False, namespace=""):
    return call(
        ros,
        srv.SpawnEntity,
        "spawn_entity",
        name=name,
        uri=uri,
        resource_string=resource_string,
        allow_renaming=allow_renaming,
        entity_namespace=namespace,
        initial_pose=at or pose(),
    )


def set_entity(
    ros,
    entity,
    x,
    y,
    z,
    q=(1.0, 0.0, 0.0, 0.0),
    linear=(0.0, 0.0, 0.0),
    angular=(0.0, 0.0, 0.0),
    frame="",
) -> Result:
    state = EntityState()
    state.header.frame_id = frame
    state.pose = pose(x, y, z, q).pose
    state.twist.linear.x, state.twist.linear.y, state.twist.linear.z = map(float, linear)
    state.twist.angular.x, state.twist.angular.y, state.twist.angular.z = map(float, angular)
    return call(ros, srv.SetEntityState, "set_entity_state", entity=entity, state=state).result


def entity_state(ros, entity):
    return call(ros, srv.GetEntityState, "get_entity_state", entity=entity)


def make_dynamic(ros, entity) -> Result:
    info = EntityInfo(category=EntityCategory(category=EntityCategory.CATEGORY_DYNAMIC_OBJECT))
    return call(ros, srv.SetEntityInfo, "set_entity_info", entity=entity, info=info).result


def xyz(p) -> list:
    return [p.x, p.y, p.z]


SPHERE = "cloth_sim://sphere?radius=0.05&friction=0.3"
BOX = "cloth_sim://box?half_extents=0.1,0.1,0.1&friction=0.5"


# ====================================================================== the defects (issue 40)
def test_defect_1_set_entity_state_teleports_a_collider_and_pushes_out_what_it_overlaps(ros):
    """Moving the table 2 m with set_entity_state is a teleport: the cloth resting on it is not
    dragged (swept, the step diverged and the node paused itself); teleported up into the cloth,
    the table pushes out what it overlaps, along its normal."""
    node = ros.start(scene="table", rows=10, cols=10, spacing=0.06, size=[0.0, 0.0])
    set_state(ros, S.STATE_PAUSED)
    assert step(ros, 800).result == Result.RESULT_OK  # the cloth settles on the table
    table = node.sim.colliders[0]
    x0 = node.sim.positions.copy()
    assert set_entity(ros, "collider/table", 2.0, 0.5, 0.35).result == Result.RESULT_OK
    assert table.position.tolist() == [2.0, 0.5, 0.35]  # there at once, before any step
    r = step(ros, 1)
    assert r.result == Result.RESULT_OK, r.error_message
    assert node.error is None and node.paused
    moved = np.abs(node.sim.positions - x0).max()
    assert moved < 1e-4  # one free-fall step of 1 ms from rest: g·dt² = 1e-5 m; not 2 m
    # back 2 cm higher than the scene has it: the part of the cloth that lay on it is now inside
    # it, and is pushed up out of it (the part draped over its edge stays outside)
    x0 = node.sim.positions.copy()
    assert set_entity(ros, "collider/table", 0.0, 0.5, 0.37).result == Result.RESULT_OK
    inside = table.signed_distance(x0) < 0
    flat = x0[:, 0] < 0.45  # well inside its edge (x = 0.5)
    assert inside[flat].all()
    assert step(ros, 1).result == Result.RESULT_OK
    h = node.sim.thickness
    assert table.signed_distance(node.sim.positions).min() >= 0.97 * h
    lift = node.sim.positions[flat] - x0[flat]
    assert np.abs(lift[:, :2]).max() < 1e-6  # out along the normal, not dragged sideways
    assert lift[:, 2] == pytest.approx(0.42 + h - x0[flat, 2], abs=0.03 * h)


def test_defect_1_pose_topics_keep_their_swept_motion(ros):
    """The pose topics stay swept: a pose streamed on ~/colliders/<name>/pose is reached over the
    next tick's steps, and friction carries what rests on the collider with it."""
    node = ros.start(scene="table", rows=10, cols=10, spacing=0.06, size=[0.0, 0.0])
    set_state(ros, S.STATE_PAUSED)
    step(ros, 800)
    table = node.sim.colliders[0]
    on_table = table.signed_distance(node.sim.positions) < 2 * node.sim.thickness
    y0 = node.sim.positions[on_table, 1].mean()
    pub = ros.node.create_publisher(PoseStamped, f"{NS}/colliders/table/pose", 10)
    target = table.position + [0.0, 0.01, 0.0]
    assert ros.spin_until(lambda: pub.get_subscription_count() > 0)
    pub.publish(pose(*target))
    assert ros.spin_until(lambda: bool(node.session.pose_targets), 5)
    step(ros, 50)
    assert table.position == pytest.approx(target)
    assert node.sim.positions[on_table, 1].mean() - y0 > 0.005  # dragged along by friction


def test_defect_2_reset_returns_the_scenes_colliders(ros):
    """reset_simulation (SCOPE_STATE, and SCOPE_DEFAULT / SCOPE_ALL) and ~/reset return the scene:
    its colliders back at their poses, deleted ones back, without twists, static again; SCOPE_STATE
    keeps a spawned collider, back where it was spawned; SCOPE_DEFAULT removes it."""
    node = ros.start(scene="table", rows=10, cols=10, spacing=0.06, size=[0.0, 0.0])
    set_state(ros, S.STATE_PAUSED)
    scene_table = node.scene.make_colliders()[0]
    assert spawn(ros, "ball", SPHERE, at=pose(0.0, 0.5, 1.5)).result.result == Result.RESULT_OK
    assert make_dynamic(ros, "table").result == Result.RESULT_OK
    assert (
        set_entity(ros, "table", 0.3, 0.6, 0.2, linear=(0.5, 0.0, 0.0)).result == Result.RESULT_OK
    )
    assert set_entity(ros, "ball", 0.0, 0.0, 2.0).result == Result.RESULT_OK
    assert (
        call(ros, srv.DeleteEntity, "delete_entity", entity="floor").result.result
        == Result.RESULT_OK
    )
    step(ros, 100)
    assert (
        call(ros, srv.ResetSimulation, "reset_simulation", scope=R.SCOPE_STATE).result.result
        == Result.RESULT_OK
    )
    names = call(ros, srv.GetEntities, "get_entities").entities
    assert names == ["cloth", "collider/table", "collider/floor", "collider/ball"]
    table = entity_state(ros, "table").state
    assert xyz(table.pose.position) == pytest.approx(scene_table.position.tolist())
    assert xyz(table.twist.linear) == [0.0, 0.0, 0.0]
    info = call(ros, srv.GetEntityInfo, "get_entity_info", entity="table").info
    assert info.category.category == EntityCategory.CATEGORY_STATIC_OBJECT
    assert xyz(entity_state(ros, "ball").state.pose.position) == pytest.approx([0.0, 0.5, 1.5])
    step(ros, 20)  # nothing moves by itself any more
    assert node.sim.colliders[0].position.tolist() == pytest.approx(scene_table.position.tolist())
    # SCOPE_DEFAULT: the spawned ball goes
    set_entity(ros, "table", 0.3, 0.6, 0.2)
    assert (
        call(ros, srv.ResetSimulation, "reset_simulation", scope=R.SCOPE_DEFAULT).result.result
        == Result.RESULT_OK
    )
    assert call(ros, srv.GetEntities, "get_entities").entities == [
        "cloth",
        "collider/table",
        "collider/floor",
    ]
    assert node.sim.colliders[0].position.tolist() == pytest.approx(scene_table.position.tolist())
    # the package's own ~/reset returns the scene too
    set_entity(ros, "table", 0.3, 0.6, 0.2)
    assert ros.call(Trigger, f"{NS}/reset", Trigger.Request()).success
    assert node.sim.colliders[0].position.tolist() == pytest.approx(scene_table.position.tolist())


def test_defect_3_generated_names_never_collide_and_an_empty_name_follows_the_standard(ros):
    """A generated name is one never used before (deleting sphere_2 and spawning again gave an
    existing name: NAME_NOT_UNIQUE). The standard: an empty name takes the resource's own; with
    none, a generated name if allow_renaming, else NAME_INVALID."""
    ros.start(scene="table", rows=8, cols=8, spacing=0.07, size=[0.0, 0.0])
    names = []
    for _ in range(2):
        r = spawn(ros, uri=SPHERE, at=pose(0, 0, 3), allow_renaming=True)
        assert r.result.result == Result.RESULT_OK
        names.append(r.entity_name)
    assert (
        call(ros, srv.DeleteEntity, "delete_entity", entity=names[0]).result.result
        == Result.RESULT_OK
    )
    r = spawn(ros, uri=SPHERE, at=pose(0, 0, 3), allow_renaming=True)
    assert r.result.result == Result.RESULT_OK
    names.append(r.entity_name)
    assert len(set(names)) == 3  # never one used before, even one deleted since
    r = spawn(ros, uri=SPHERE, at=pose(0, 0, 3)).result
    assert (
        r.result == srv.SpawnEntity.Response.NAME_INVALID and "allow_renaming" in r.error_message
    )
    r = spawn(ros, resource_string="{type: sphere, name: marble, radius: 0.05}", at=pose(0, 0, 3))
    assert r.result.result == Result.RESULT_OK and r.entity_name == "collider/marble"


def test_defect_4_the_name_a_client_spawns_is_a_name_it_can_use(ros):
    """spawn_entity {name: ball} answers collider/ball; ball and collider/ball both address it in
    every service (get/set state, bounds, info, delete), as Gazebo's docs and RobotecAI's script
    spawn and then delete by the name they gave."""
    ros.start(scene="free_fall", rows=8, cols=8, spacing=0.05)
    r = spawn(ros, "ball", SPHERE, at=pose(0.2, 0.2, -0.5))
    assert r.result.result == Result.RESULT_OK and r.entity_name == "collider/ball"
    z = -0.5
    for name in ("ball", r.entity_name):
        got = entity_state(ros, name)
        assert got.result.result == Result.RESULT_OK
        assert xyz(got.state.pose.position) == pytest.approx([0.2, 0.2, z])
        z -= 0.1
        assert set_entity(ros, name, 0.2, 0.2, z).result == Result.RESULT_OK
        b = call(ros, srv.GetEntityBounds, "get_entity_bounds", entity=name)
        assert b.result.result == Result.RESULT_OK and b.bounds.type == Bounds.TYPE_BOX
        assert (
            call(ros, srv.GetEntityInfo, "get_entity_info", entity=name).result.result
            == Result.RESULT_OK
        )
    assert (
        call(ros, srv.DeleteEntity, "delete_entity", entity="ball").result.result
        == Result.RESULT_OK
    )
    r = entity_state(ros, "ball").result
    assert r.result == Result.RESULT_NOT_FOUND and "ball" in r.error_message


def test_defect_5_poses_in_the_world_frame_or_no_frame_are_accepted(ros):
    """initial_pose (and a state) in the node's world_frame_id ('world', which /tf_static makes
    the cloth frame), its frame_id, or an empty frame (the standard's default) are accepted; any
    other frame is refused, naming those."""
    node = ros.start(scene="free_fall", rows=8, cols=8, spacing=0.05)
    for i, frame in enumerate(("world", "cloth", "")):
        r = spawn(ros, f"ball_{frame or 'none'}", SPHERE, at=pose(i, 0, -1, frame=frame)).result
        assert r.result == Result.RESULT_OK, (frame, r.error_message)
        assert node.sim.colliders[-1].position.tolist() == [float(i), 0.0, -1.0]
    assert set_entity(ros, "ball_world", 0, 1, -1, frame="world").result == Result.RESULT_OK
    r = spawn(ros, "ball_map", SPHERE, at=pose(0, 0, -1, frame="map")).result
    assert r.result == srv.SpawnEntity.Response.INVALID_POSE
    assert "'cloth' or 'world'" in r.error_message and "empty" in r.error_message


def test_defect_6_a_static_object_refuses_a_twist_and_a_dynamic_one_moves_at_it(ros):
    """Colliders are STATIC_OBJECTs: a twist (or acceleration) for one fails with OPERATION_FAILED
    and changes nothing, as SetEntityState.srv says (it used to move). set_entity_info makes one a
    DYNAMIC_OBJECT, a kinematic obstacle that then moves at the twist it is given."""
    node = ros.start(scene="drape", rows=8, cols=8, spacing=1.0 / 7)
    set_state(ros, S.STATE_PAUSED)
    ball = node.sim.colliders[0]
    p0 = ball.position.copy()
    info = call(ros, srv.GetEntityInfo, "get_entity_info", entity="ball").info
    assert info.category.category == EntityCategory.CATEGORY_STATIC_OBJECT
    r = set_entity(ros, "ball", *p0, linear=(0.1, 0.0, 0.0))
    assert r.result == Result.RESULT_OPERATION_FAILED and "STATIC_OBJECT" in r.error_message
    state = EntityState()
    state.pose = pose(*p0).pose
    state.acceleration.linear.z = 1.0
    r = call(ros, srv.SetEntityState, "set_entity_state", entity="ball", state=state).result
    assert r.result == Result.RESULT_OPERATION_FAILED
    step(ros, 100)
    np.testing.assert_array_equal(ball.position, p0)
    assert make_dynamic(ros, "ball").result == Result.RESULT_OK
    info = call(ros, srv.GetEntityInfo, "get_entity_info", entity="ball").info
    assert info.category.category == EntityCategory.CATEGORY_DYNAMIC_OBJECT
    assert set_entity(ros, "ball", *p0, linear=(0.1, 0.0, 0.0)).result == Result.RESULT_OK
    step(ros, 100)
    assert ball.position == pytest.approx(p0 + [0.1 * 100 * node.sim.dt, 0.0, 0.0], abs=1e-12)
    # the cloth's and a gripper's categories are theirs
    r = make_dynamic(ros, "cloth")
    assert r.result == Result.RESULT_OPERATION_FAILED and "CATEGORY_OBJECT" in r.error_message


def test_defect_7_bounds_are_boxes_a_namespace_is_unsupported_and_states_are_named(ros):
    """A sphere's bounds: TYPE_BOX (GetEntityBounds.srv: 'Bounds with TYPE_BOX should be
    returned'); entity_namespace: FEATURE_UNSUPPORTED (the truth, not NAMESPACE_INVALID); an
    unknown state: refused naming the states, not 'no worlds to load'."""
    node = ros.start(scene="drape", rows=8, cols=8, spacing=1.0 / 7)
    b = call(ros, srv.GetEntityBounds, "get_entity_bounds", entity="collider/ball").bounds
    c = node.sim.colliders[0]
    assert b.type == Bounds.TYPE_BOX
    assert xyz(b.points[0]) + xyz(b.points[1]) == pytest.approx(
        (c.center - c.radius).tolist() + (c.center + c.radius).tolist()
    )
    r = spawn(ros, "thing", SPHERE, namespace="robot1").result
    assert r.result == Result.RESULT_FEATURE_UNSUPPORTED and "namespace" in r.error_message
    r = set_state(ros, 7)
    assert r.result == Result.RESULT_OPERATION_FAILED and "STATE_PAUSED" in r.error_message
    assert "world" not in r.error_message
    r = set_state(ros, S.STATE_NO_WORLD)
    assert r.result == Result.RESULT_FEATURE_UNSUPPORTED and "worlds" in r.error_message


def test_defect_8_ctrl_c_of_the_tshirt_scene_prints_no_leak_warnings():
    """The tshirt scene (liu2013: a cholespy factorisation) ended by SIGINT exits 0 with nothing
    on stderr about leaked nanobind instances (the solver used to outlive the interpreter)."""
    proc = start_node(next_domain(), "-p", "scene:=tshirt")
    time.sleep(3.0)
    proc.send_signal(signal.SIGINT)
    code, out = end_node(proc, timeout=60)
    assert code == 0, out[-3000:]
    assert "scene tshirt" in out
    assert "leaked" not in out and "nanobind" not in out, out[-3000:]


def test_an_already_reached_state_is_answered_as_the_standard_says(ros):
    ros.start()
    Already = srv.SetSimulationState.Response.ALREADY_IN_TARGET_STATE
    assert set_state(ros, S.STATE_PLAYING).result == Already
    assert set_state(ros, S.STATE_PAUSED).result == Result.RESULT_OK
    assert set_state(ros, S.STATE_PAUSED).result == Already
    assert set_state(ros, S.STATE_STOPPED).result == Result.RESULT_OK
    assert set_state(ros, S.STATE_STOPPED).result == Already
    assert (
        set_state(ros, S.STATE_PLAYING).result == Result.RESULT_OK
        and get_state(ros) == S.STATE_PLAYING
    )


def test_entities_filter_by_tags_and_by_bounds(ros):
    """EntityFilters: tags (set with set_entity_info; ANY and ALL), and the overlap filter with a
    sphere (every shape exactly) and a box; a convex hull is FEATURE_UNSUPPORTED."""
    ros.start(scene="table", rows=8, cols=8, spacing=0.07, size=[0.0, 0.0])
    info = EntityInfo(
        category=EntityCategory(category=EntityCategory.CATEGORY_STATIC_OBJECT),
        description="the work surface",
        tags=["furniture", "surface"],
    )
    assert (
        call(ros, srv.SetEntityInfo, "set_entity_info", entity="table", info=info).result.result
        == Result.RESULT_OK
    )
    got = call(ros, srv.GetEntityInfo, "get_entity_info", entity="table").info
    assert got.description == "the work surface" and list(got.tags) == ["furniture", "surface"]

    def names(**filters):
        r = call(ros, srv.GetEntities, "get_entities", filters=EntityFilters(**filters))
        assert r.result.result == Result.RESULT_OK, r.result.error_message
        return r.entities

    assert names(tags=TagsFilter(tags=["surface", "x"])) == ["collider/table"]
    assert (
        names(tags=TagsFilter(tags=["surface", "x"], filter_mode=TagsFilter.FILTER_MODE_ALL)) == []
    )
    from geometry_msgs.msg import Vector3

    # a sphere at the table's top corner touches only the table (the floor is 0.3 m below)
    near = Bounds(
        type=Bounds.TYPE_SPHERE, points=[Vector3(x=0.55, y=1.25, z=0.45), Vector3(x=0.1)]
    )
    assert names(bounds=near) == ["collider/table"]
    low = Bounds(
        type=Bounds.TYPE_BOX,
        points=[Vector3(x=-5.0, y=-5.0, z=-1.0), Vector3(x=5.0, y=5.0, z=0.1)],
    )
    assert names(bounds=low) == ["collider/floor"]
    hull = Bounds(type=Bounds.TYPE_CONVEX_HULL, points=[Vector3(), Vector3(x=1.0), Vector3(y=1.0)])
    r = call(ros, srv.GetEntities, "get_entities", filters=EntityFilters(bounds=hull)).result
    assert r.result == Result.RESULT_FEATURE_UNSUPPORTED


# ====================================================================== Gazebo (ros_gz_sim)
# gazebosim/ros_gz: ros_gz_sim/test/test_gz_simulation_interfaces.launch.py
def test_gazebo_get_entities_with_no_filters(ros):
    ros.start()
    r = call(ros, srv.GetEntities, "get_entities")
    assert r.result.result == Result.RESULT_OK
    assert r.result.error_message == ""
    assert r.entities


def test_gazebo_get_entity_state(ros):
    """Gazebo drives its vehicle at 0.25 m/s through cmd_vel and reads the twist back. cloth_sim
    has no vehicle: a collider made a DYNAMIC_OBJECT is set moving at 0.25 m/s instead."""
    ros.start(scene="table", rows=8, cols=8, spacing=0.07, size=[0.0, 0.0])
    r = entity_state(ros, "table")
    assert r.result.result == Result.RESULT_OK and r.result.error_message == ""
    assert r.state.twist.linear.x == pytest.approx(0.0, abs=1e-4)
    p = r.state.pose.position
    make_dynamic(ros, "table")
    set_entity(ros, "table", p.x, p.y, p.z, linear=(0.25, 0.0, 0.0))
    ros.spin_for(0.5)
    r = entity_state(ros, "table")
    assert r.state.twist.linear.x == pytest.approx(0.25, abs=1e-2)
    assert r.state.pose.position.x > p.x  # and it moved at it while playing


def test_gazebo_get_entity_state_on_spawned_entity(ros):
    """Spawned by name from a resource string, its state is read by that name. Gazebo then expects
    the ball to roll down an incline (twist.x > 0.1): cloth_sim's colliders are kinematic (no
    rigid-body dynamics), so that part does not apply (README, simulation_interfaces)."""
    ros.start()
    r = spawn(
        ros, "test_sphere", resource_string="{type: sphere, radius: 1.0}", at=pose(4.0, -20.0, 4.0)
    )
    assert r.result.result == Result.RESULT_OK
    state = entity_state(ros, "test_sphere")
    assert state.result.result == Result.RESULT_OK and state.result.error_message == ""
    assert xyz(state.state.pose.position) == pytest.approx([4.0, -20.0, 4.0])


# gazebosim/ros_gz: ros_gz_sim/test/test_gz_simulation_interfaces_spawn_entity.cpp
def test_gazebo_spawn_entity_with_a_namespace(ros):
    """Gazebo forwards entity_namespace to the spawned model's interfaces. A cloth_sim collider
    has no ROS interfaces of its own: FEATURE_UNSUPPORTED, and nothing is spawned."""
    ros.start()
    before = call(ros, srv.GetEntities, "get_entities").entities
    r = spawn(ros, "test_model", SPHERE, namespace="test_ns").result
    assert r.result == Result.RESULT_FEATURE_UNSUPPORTED
    assert call(ros, srv.GetEntities, "get_entities").entities == before


# ====================================================================== Isaac Sim
# isaac-sim/IsaacSim: source/extensions/isaacsim.ros2.sim_control/python/tests/
# test_sim_control_services.py
def test_isaac_get_simulator_features_service(ros):
    """Isaac compares its own list; the intent kept: features, spawn formats and custom info are
    given, and every service a feature names answers (none answers FEATURE_UNSUPPORTED)."""
    ros.start()
    f = call(ros, srv.GetSimulatorFeatures, "get_simulator_features").features
    assert list(f.features) == sorted(f.features) and f.spawn_formats and f.custom_info
    for feature, kind, name in [
        (SimulatorFeatures.SPAWNABLES, srv.GetSpawnables, "get_spawnables"),
        (SimulatorFeatures.ENTITY_INFO_GETTING, srv.GetEntityInfo, "get_entity_info"),
        (
            SimulatorFeatures.SIMULATION_STATE_GETTING,
            srv.GetSimulationState,
            "get_simulation_state",
        ),
    ]:
        assert feature in f.features
        fields = {"entity": "cloth"} if kind is srv.GetEntityInfo else {}
        assert call(ros, kind, name, **fields).result.result == Result.RESULT_OK


def test_isaac_get_simulation_state_service(ros):
    """Isaac starts stopped and drives its timeline; cloth_sim starts playing and is driven through
    set_simulation_state. Each state is reported."""
    ros.start()
    assert get_state(ros) == S.STATE_PLAYING
    set_state(ros, S.STATE_PAUSED)
    assert get_state(ros) == S.STATE_PAUSED
    set_state(ros, S.STATE_STOPPED)
    assert get_state(ros) == S.STATE_STOPPED
    set_state(ros, S.STATE_PLAYING)
    assert get_state(ros) == S.STATE_PLAYING


def test_isaac_set_simulation_state_service(ros):
    node = ros.start()
    assert set_state(ros, S.STATE_STOPPED).result == Result.RESULT_OK
    assert node.paused and node.sim.time == 0.0
    assert set_state(ros, S.STATE_PLAYING).result == Result.RESULT_OK and not node.paused
    assert set_state(ros, S.STATE_PAUSED).result == Result.RESULT_OK and node.paused
    assert set_state(ros, S.STATE_STOPPED).result == Result.RESULT_OK
    assert node.paused and node.sim.time == 0.0


def test_isaac_get_entities_service(ros):
    node = ros.start(scene="drape", rows=8, cols=8, spacing=1.0 / 7)
    names = call(ros, srv.GetEntities, "get_entities").entities
    assert names
    for expected in ["cloth", *(f"collider/{c.name}" for c in node.sim.colliders)]:
        assert expected in names


def test_isaac_get_entity_info_service(ros):
    """Isaac reports OBJECT for its cube and cone; cloth_sim's categories are its own: the cloth
    OBJECT, a collider STATIC_OBJECT, a gripper ROBOT."""
    from cloth_sim.srv import Grasp

    node = ros.start(scene="drape", rows=8, cols=8, spacing=1.0 / 7)
    corner = Point(**dict(zip("xyz", node.sim.positions[0].tolist())))
    assert ros.call(
        Grasp, f"{NS}/grasp", Grasp.Request(gripper="hand", point=corner, radius=0.01)
    ).success
    for entity, category in [
        ("cloth", EntityCategory.CATEGORY_OBJECT),
        ("collider/ball", EntityCategory.CATEGORY_STATIC_OBJECT),
        ("gripper/hand", EntityCategory.CATEGORY_ROBOT),
    ]:
        r = call(ros, srv.GetEntityInfo, "get_entity_info", entity=entity)
        assert r.result.result == Result.RESULT_OK and r.info.category.category == category
        assert r.info.description


def test_isaac_get_entity_state_service(ros):
    """A pose set is read back (Isaac sets its prims directly; here through set_entity_state); a
    static object's twist is zero."""
    ros.start(scene="drape", rows=8, cols=8, spacing=1.0 / 7)
    q = np.array([0.707, 0.0, 0.0, 0.707]) / np.linalg.norm([0.707, 0.0, 0.0, 0.707])
    assert set_entity(ros, "ball", 3.0, 4.0, 1.0, q=q).result == Result.RESULT_OK
    r = entity_state(ros, "ball")
    assert r.result.result == Result.RESULT_OK
    assert xyz(r.state.pose.position) == [3.0, 4.0, 1.0]
    assert xyz(r.state.twist.linear) == [0.0, 0.0, 0.0] and xyz(r.state.twist.angular) == [0.0] * 3


def test_isaac_get_entities_states_service(ros):
    """A regular expression selects entities and their states (Isaac's 'Objects' and
    '^/World/Objects/': here 'coll' and '^collider/')."""
    node = ros.start(scene="table", rows=8, cols=8, spacing=0.07, size=[0.0, 0.0])
    r = call(
        ros, srv.GetEntitiesStates, "get_entities_states", filters=EntityFilters(filter="coll")
    )
    assert r.result.result == Result.RESULT_OK and len(r.entities) == len(r.states) == 2
    set_entity(ros, "floor", 0.0, 0.0, -0.1)
    r = call(
        ros,
        srv.GetEntitiesStates,
        "get_entities_states",
        filters=EntityFilters(filter="^collider/"),
    )
    assert len(r.entities) == len(r.states) == 2
    floor = r.states[r.entities.index("collider/floor")]
    assert xyz(floor.pose.position) == [0.0, 0.0, -0.1]
    table = r.states[r.entities.index("collider/table")]
    assert xyz(table.pose.position) == pytest.approx(node.sim.colliders[0].position.tolist())


def test_isaac_set_entity_state_service(ros):
    """A moving object gets its pose and twist, while playing and while stopped. Isaac's static
    cone takes a twist and ignores it; SetEntityState.srv says a twist for a static object fails
    with OPERATION_FAILED: the standard is followed, and the pose alone is then set exactly."""
    node = ros.start(scene="drape", rows=8, cols=8, spacing=1.0 / 7)
    assert spawn(ros, "cube", BOX, at=pose(0.0, 0.0, 2.0)).result.result == Result.RESULT_OK
    make_dynamic(ros, "cube")
    r = set_entity(ros, "cube", 2.5, 3.0, 4.0, linear=(1.0, 2.0, 3.0), angular=(0.1, 0.2, 0.3))
    assert r.result == Result.RESULT_OK
    s = entity_state(ros, "cube").state
    assert xyz(s.pose.position) == pytest.approx([2.5, 3.0, 4.0], abs=0.2)
    assert xyz(s.twist.linear) == [1.0, 2.0, 3.0] and xyz(s.twist.angular) == [0.1, 0.2, 0.3]
    q = (0.707, 0.0, 0.0, 0.707)
    r = set_entity(
        ros, "ball", 5.0, 6.0, 2.0, q=q, linear=(5.0, 6.0, 7.0), angular=(0.5, 0.6, 0.7)
    )
    assert r.result == Result.RESULT_OPERATION_FAILED  # the standard (Isaac: OK, twist ignored)
    assert set_entity(ros, "ball", 5.0, 6.0, 2.0, q=q).result == Result.RESULT_OK
    assert node.sim.colliders[0].position.tolist() == [5.0, 6.0, 2.0]
    set_state(ros, S.STATE_STOPPED)
    assert (
        set_entity(ros, "cube", 1.5, 2.5, 3.5, linear=(0.5, 1.5, 2.5)).result == Result.RESULT_OK
    )
    assert xyz(entity_state(ros, "cube").state.pose.position) == [1.5, 2.5, 3.5]
    assert set_entity(ros, "ball", 4.5, 5.5, 1.5).result == Result.RESULT_OK
    assert node.sim.colliders[0].position.tolist() == [4.5, 5.5, 1.5]


def test_isaac_spawn_entity_basic_default_position(ros):
    """Delete an entity of the scene, then spawn one without a pose: at the origin, identity."""
    ros.start(scene="drape", rows=8, cols=8, spacing=1.0 / 7)
    assert (
        call(ros, srv.DeleteEntity, "delete_entity", entity="ball").result.result
        == Result.RESULT_OK
    )
    assert "collider/ball" not in call(ros, srv.GetEntities, "get_entities").entities
    r = call(
        ros, srv.SpawnEntity, "spawn_entity", name="BasicEntity", allow_renaming=False, uri=BOX
    )
    assert r.result.result == Result.RESULT_OK
    s = entity_state(ros, "BasicEntity").state.pose
    assert xyz(s.position) == pytest.approx([0.0, 0.0, 0.0], abs=0.01)
    assert [s.orientation.w, s.orientation.x, s.orientation.y, s.orientation.z] == pytest.approx(
        [1.0, 0.0, 0.0, 0.0], abs=0.01
    )


def test_isaac_spawn_entity_with_position_orientation(ros):
    ros.start()
    q = (0.707, 0.0, 0.0, 0.707)
    r = spawn(ros, "PositionedEntity", BOX, at=pose(1.0, 2.0, 3.0, q=q))
    assert r.result.result == Result.RESULT_OK
    s = entity_state(ros, "PositionedEntity").state.pose
    assert xyz(s.position) == pytest.approx([1.0, 2.0, 3.0], abs=0.01)
    got = np.array([s.orientation.w, s.orientation.x, s.orientation.y, s.orientation.z])
    assert got == pytest.approx(np.array(q), abs=0.01) or -got == pytest.approx(
        np.array(q), abs=0.01
    )


def test_isaac_spawn_entity_auto_renaming(ros):
    ros.start()
    assert spawn(ros, "DuplicateEntity", BOX).result.result == Result.RESULT_OK
    r = spawn(ros, "DuplicateEntity", BOX, allow_renaming=True)
    assert r.result.result == Result.RESULT_OK and r.entity_name == "collider/DuplicateEntity_1"
    assert "collider/DuplicateEntity" in call(ros, srv.GetEntities, "get_entities").entities


def test_isaac_spawn_entity_with_namespace(ros):
    """Isaac spawns under a namespace and finds the robot's topics there; a cloth_sim collider has
    no topics of its own under a namespace: FEATURE_UNSUPPORTED (does not apply)."""
    ros.start()
    r = spawn(ros, "NamespacedEntity", BOX, namespace="robot1").result
    assert r.result == Result.RESULT_FEATURE_UNSUPPORTED


def test_isaac_spawn_entity_error_cases(ros):
    """NAME_NOT_UNIQUE; an empty name with allow_renaming false takes the resource's own name
    (Isaac: the USD's default prim, 'limo'); a resource that is not cloth_sim's format:
    UNSUPPORTED_FORMAT (Isaac answers RESOURCE_PARSE_ERROR for a missing file; the standard's code
    for a format the simulator does not read is UNSUPPORTED_FORMAT); a cloth_sim resource that
    does not parse: RESOURCE_PARSE_ERROR."""
    ros.start()
    Res = srv.SpawnEntity.Response
    assert spawn(ros, "ExistingEntity", BOX).result.result == Result.RESULT_OK
    assert spawn(ros, "ExistingEntity", BOX).result.result == Res.NAME_NOT_UNIQUE
    r = spawn(ros, "", resource_string="{type: box, name: limo, half_extents: [0.2, 0.1, 0.1]}")
    assert r.result.result == Result.RESULT_OK and r.entity_name == "collider/limo"
    assert (
        spawn(ros, "InvalidEntity", "/invalid/path/to/nonexistent.usd").result.result
        == Res.UNSUPPORTED_FORMAT
    )
    assert (
        spawn(ros, "InvalidEntity", "cloth_sim://box?half_extents=-1,0,0").result.result
        == Res.RESOURCE_PARSE_ERROR
    )


def test_isaac_delete_entity_service(ros):
    ros.start()
    assert spawn(ros, "EntityToDelete", BOX).result.result == Result.RESULT_OK
    r = call(ros, srv.DeleteEntity, "delete_entity", entity="EntityToDelete").result
    assert r.result == Result.RESULT_OK
    assert "collider/EntityToDelete" not in call(ros, srv.GetEntities, "get_entities").entities
    r = call(ros, srv.DeleteEntity, "delete_entity", entity="NonExistentEntity").result
    assert r.result == Result.RESULT_NOT_FOUND


def test_isaac_reset_simulation_service(ros):
    """SCOPE_DEFAULT removes what was spawned, keeps the scene's entities, resets the state."""
    node = ros.start(scene="drape", rows=8, cols=8, spacing=1.0 / 7)
    assert spawn(ros, "SpawnedForReset", BOX, at=pose(0, 0, -1)).result.result == Result.RESULT_OK
    ros.spin_for(0.3)  # playing: the cloth falls
    assert not np.array_equal(node.sim.positions, node.sim.model.positions)
    # paused first: a reset keeps the simulation playing, and a tick after it moves the cloth again
    set_state(ros, S.STATE_PAUSED)
    r = call(ros, srv.ResetSimulation, "reset_simulation", scope=R.SCOPE_DEFAULT).result
    assert r.result == Result.RESULT_OK
    names = call(ros, srv.GetEntities, "get_entities").entities
    assert "collider/SpawnedForReset" not in names
    assert "cloth" in names and "collider/ball" in names and "collider/floor" in names
    np.testing.assert_array_equal(node.sim.positions, node.sim.model.positions)


def test_isaac_step_simulation_service(ros):
    """Paused, 1, 2 and 5 steps each move the falling cloth further and leave it paused, the
    message saying how many steps (Isaac: '1 frames'). Stepping while playing: StepSimulation.srv
    says RESULT_OPERATION_FAILED (Isaac expects RESULT_INCORRECT_STATE); the standard is
    followed."""
    node = ros.start(scene="free_fall", rows=8, cols=8, spacing=0.05)
    set_state(ros, S.STATE_PAUSED)
    z = node.sim.positions[:, 2].mean()
    for n in (1, 2, 5):
        r = step(ros, n)
        assert r.result == Result.RESULT_OK and f"{n} step" in r.error_message
        assert get_state(ros) == S.STATE_PAUSED
        z, z_before = node.sim.positions[:, 2].mean(), z
        assert z < z_before
    set_state(ros, S.STATE_PLAYING)
    assert step(ros, 1).result == Result.RESULT_OPERATION_FAILED


def test_isaac_simulate_steps_action(ros):
    """5 steps through the action: OK, still paused, the cloth moved. While playing:
    SimulateSteps.action says OPERATION_FAILED (Isaac expects INCORRECT_STATE); the standard is
    followed."""
    node = ros.start(scene="free_fall", rows=8, cols=8, spacing=0.05)
    set_state(ros, S.STATE_PAUSED)
    z = node.sim.positions[:, 2].mean()
    client = ActionClient(ros.node, SimulateSteps, f"{NS}/simulate_steps")
    assert ros.spin_until(client.server_is_ready, 10)

    def run(steps):
        fut = client.send_goal_async(SimulateSteps.Goal(steps=steps))
        assert ros.spin_until(fut.done, 10) and fut.result().accepted
        res = fut.result().get_result_async()
        assert ros.spin_until(res.done, 20)
        return res.result().result.result

    assert run(5).result == Result.RESULT_OK
    assert get_state(ros) == S.STATE_PAUSED
    assert node.sim.positions[:, 2].mean() < z
    set_state(ros, S.STATE_PLAYING)
    assert run(3).result == Result.RESULT_OPERATION_FAILED


def test_isaac_worlds_do_not_apply(ros):
    """load_world, get_current_world, unload_world, get_available_worlds: cloth_sim has no worlds
    (its scene is a parameter), so each answers FEATURE_UNSUPPORTED with a message, at once."""
    ros.start()
    features = call(ros, srv.GetSimulatorFeatures, "get_simulator_features").features.features
    assert SimulatorFeatures.WORLD_LOADING not in features
    for kind, name in [
        (srv.LoadWorld, "load_world"),
        (srv.GetCurrentWorld, "get_current_world"),
        (srv.UnloadWorld, "unload_world"),
        (srv.GetAvailableWorlds, "get_available_worlds"),
    ]:
        r = call(ros, kind, name).result
        assert r.result == Result.RESULT_FEATURE_UNSUPPORTED and r.error_message


def test_isaac_spawn_entities_batch_service(ros):
    ros.start()

    def one(name, uri, at=None):
        return SpawnEntityMsg(
            name=name, entity_resource=Resource(uri=uri), initial_pose=at or pose()
        )

    r = call(
        ros,
        srv.SpawnEntities,
        "spawn_entities",
        spawn_requests=[one("BatchRobot", BOX, pose(1.0, 2.0, 0.0)), one("BatchXform", SPHERE)],
    )
    assert r.result.result == Result.RESULT_OK and len(r.results) == 2
    assert [x.result.result for x in r.results] == [Result.RESULT_OK] * 2
    assert [x.entity_name for x in r.results] == ["collider/BatchRobot", "collider/BatchXform"]
    assert xyz(entity_state(ros, "BatchRobot").state.pose.position) == pytest.approx(
        [1.0, 2.0, 0.0]
    )
    r = call(
        ros,
        srv.SpawnEntities,
        "spawn_entities",
        spawn_requests=[
            one("BatchValid", SPHERE),
            one("BatchInvalid", "/invalid/nonexistent.usd"),
        ],
    )
    assert (
        r.result.result == srv.SpawnEntities.Response.ENTITIES_SPAWN_FAILED and len(r.results) == 2
    )
    assert (
        r.results[0].result.result == Result.RESULT_OK
        and r.results[0].entity_name == "collider/BatchValid"
    )
    assert r.results[1].result.result != Result.RESULT_OK
    assert "collider/BatchValid" in call(ros, srv.GetEntities, "get_entities").entities


def test_isaac_get_entity_bounds_service(ros):
    """A unit cube at (0, 0, 2) spans (-0.5, -0.5, 1.5) to (0.5, 0.5, 2.5); an unknown entity is
    NOT_FOUND."""
    ros.start()
    spawn(ros, "DynamicCube", "cloth_sim://box?half_extents=0.5,0.5,0.5", at=pose(0, 0, 2))
    r = call(ros, srv.GetEntityBounds, "get_entity_bounds", entity="DynamicCube")
    assert r.result.result == Result.RESULT_OK and r.bounds.type == Bounds.TYPE_BOX
    assert len(r.bounds.points) == 2
    assert xyz(r.bounds.points[0]) == pytest.approx([-0.5, -0.5, 1.5], abs=0.01)
    assert xyz(r.bounds.points[1]) == pytest.approx([0.5, 0.5, 2.5], abs=0.01)
    r = call(ros, srv.GetEntityBounds, "get_entity_bounds", entity="NonExistentPrim")
    assert r.result.result == Result.RESULT_NOT_FOUND


def test_isaac_get_spawnables_service(ros):
    """Default sources: every spawnable has a URI and a description, its spawn bounds empty; with
    additional sources the call still succeeds (GetSpawnables.srv: unrecognised sources are named
    in error_message and do not hinder success)."""
    ros.start()
    r = call(ros, srv.GetSpawnables, "get_spawnables")
    assert r.result.result == Result.RESULT_OK and r.spawnables
    for s in r.spawnables:
        assert s.uri and s.description and s.spawn_bounds.type == Bounds.TYPE_EMPTY
    r = call(ros, srv.GetSpawnables, "get_spawnables", sources=["/Isaac/Samples/ROS2/Robots"])
    assert r.result.result == Result.RESULT_OK and r.spawnables
    assert "/Isaac/Samples/ROS2/Robots" in r.result.error_message


# ====================================================================== RobotecAI
def test_robotec_warehouse_script(ros):
    """RobotecAI/simulation_interfaces_examples: warehouse_simulation_script.py's sequence with the
    gazebo backend's naming (no prefix): get features; spawn a table by name and delete it by that
    name; spawn the scene (table, cubes, a Dingo and a UR10, here boxes standing in); play, pause;
    reset SCOPE_STATE; move two cubes with a pose whose frame is empty; step 2 × 15 while paused;
    play, spawn obstacle boxes and place the Dingo. The script then drives the Dingo with cmd_vel
    and the UR10 with its joints: cloth_sim has no robots, so that part does not apply. Every
    service call of the script must succeed."""
    ros.start(rows=10, cols=10, spacing=0.1)
    calls = []

    def check(what, r):
        calls.append((what, r.result, r.error_message))

    features = call(ros, srv.GetSimulatorFeatures, "get_simulator_features").features
    assert SimulatorFeatures.WORLD_LOADING not in features.features  # the script skips load_world
    check(
        "spawn Table",
        spawn(ros, "Table", BOX, at=pose(0.0, 0.0, 1.19), allow_renaming=True).result,
    )
    check("delete Table", call(ros, srv.DeleteEntity, "delete_entity", entity="Table").result)
    yaw = (math.cos(0.7854), 0.0, 0.0, math.sin(0.7854))
    for name, at in [
        ("Table", pose(-1.0, -1.5, 1.19, yaw)),
        ("Dingo", pose(-4.0, -3.0, 0.0)),
        ("UR10", pose(-1.0, -2.14, 1.19, yaw)),
    ]:
        check(f"spawn {name}", spawn(ros, name, BOX, at=at, allow_renaming=True).result)
    cubes = [
        ((0.2, 0.2), "blue"),
        ((-0.2, 0.2), "red"),
        ((0.2, -0.2), "red"),
        ((-0.2, -0.2), "blue"),
        ((0.0, 0.0), "blue"),
        ((0.1, 0.0), "red"),
        ((-0.1, 0.0), "red"),
    ]
    for i, ((dx, dy), color) in enumerate(cubes):
        check(
            f"spawn {color}_cube_{i}",
            spawn(
                ros,
                f"{color}_cube_{i}",
                BOX,
                allow_renaming=True,
                at=pose(-1.0 + dx, -1.5 + dy, 1.34),
            ).result,
        )
    check(
        "play",
        set_state(ros, S.STATE_PLAYING)
        if get_state(ros) != S.STATE_PLAYING
        else Result(result=Result.RESULT_OK),
    )
    ros.spin_for(0.3)
    check("pause", set_state(ros, S.STATE_PAUSED))
    check(
        "reset SCOPE_STATE",
        call(ros, srv.ResetSimulation, "reset_simulation", scope=R.SCOPE_STATE).result,
    )
    check("move blue_cube_0", set_entity(ros, "blue_cube_0", -0.8, -1.3, 1.59))
    check("move red_cube_1", set_entity(ros, "red_cube_1", -1.2, -1.3, 1.59))
    for k in range(15):
        check(f"step {k}", step(ros, 2))
    check("play again", set_state(ros, S.STATE_PLAYING))
    for it, boxes in enumerate(
        [
            [(-2.5, -2.5, 0.0), (-0.5, -3.5, 1.5708), (-1.8, -3.3, 0.7854)],
            [(-3.0, -1.0, 1.5708), (0.5, -2.0, 0.0), (0.8, -0.3, 0.7854)],
        ]
    ):
        for i, (x, y, a) in enumerate(boxes):
            q = (math.cos(a / 2), 0.0, 0.0, math.sin(a / 2))
            check(
                f"spawn obstacle_box_{it}_{i}",
                spawn(
                    ros, f"obstacle_box_{it}_{i}", BOX, at=pose(x, y, 0.0, q), allow_renaming=True
                ).result,
            )
        check(f"place Dingo {it}", set_entity(ros, "Dingo", -4.0, -2.5 + 3 * it, 0.0))
        check(f"read Dingo {it}", entity_state(ros, "Dingo").result)
    failed = [c for c in calls if c[1] != Result.RESULT_OK]
    assert not failed, failed
    assert len(calls) == 43
