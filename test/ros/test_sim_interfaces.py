"""The ROS simulation standard (simulation_interfaces) through rclpy clients: every advertised
feature does what the standard says, a feature not advertised answers with the standard's error
result, and bad requests get the standard's codes with a message."""

import math

import numpy as np
import pytest
from geometry_msgs.msg import WrenchStamped
from rclpy.action import ActionClient
from simulation_interfaces import srv
from simulation_interfaces.action import SimulateSteps
from simulation_interfaces.msg import (
    EntityCategory,
    EntityInfo,
    Result,
    SimulationState,
    SimulatorFeatures,
)

from cloth_sim.msg import Stats
from cloth_sim.ros.sim_interfaces import FEATURES, UNSUPPORTED

NS = "/cloth_sim"


def call(ros, kind, name, **fields):
    return ros.call(kind, f"{NS}/{name}", kind.Request(**fields))


def set_state(ros, state):
    return call(
        ros, srv.SetSimulationState, "set_simulation_state", state=SimulationState(state=state)
    ).result


def test_features_are_stated_and_unsupported_services_answer_with_the_standard_result(ros):
    ros.start()
    features = call(ros, srv.GetSimulatorFeatures, "get_simulator_features").features
    assert sorted(features.features) == sorted(FEATURES)
    assert SimulatorFeatures.STEP_SIMULATION_ACTION in features.features
    assert SimulatorFeatures.SPAWNING in features.features and features.spawn_formats
    for name, kind in UNSUPPORTED.items():
        r = ros.call(kind, f"{NS}/{name}", kind.Request()).result
        assert r.result == Result.RESULT_FEATURE_UNSUPPORTED and name in r.error_message


def test_state_changes_are_visible_in_stats_and_follow_the_standard_transitions(ros):
    node = ros.start()
    stats = ros.collect(Stats, f"{NS}/stats")

    def get():
        return call(ros, srv.GetSimulationState, "get_simulation_state").state.state

    S = SimulationState
    assert get() == S.STATE_PLAYING
    assert (
        set_state(ros, S.STATE_PLAYING).result
        == srv.SetSimulationState.Response.ALREADY_IN_TARGET_STATE
    )
    assert set_state(ros, S.STATE_PAUSED).result == Result.RESULT_OK and get() == S.STATE_PAUSED
    n = len(stats)
    assert ros.spin_until(lambda: len(stats) > n + 3 and stats[-1].paused)
    t = node.sim.time
    ros.spin_for(0.3)
    assert node.sim.time == t  # paused: no step
    assert set_state(ros, S.STATE_STOPPED).result == Result.RESULT_OK and get() == S.STATE_STOPPED
    assert node.sim.time == 0.0 and node.paused
    np.testing.assert_array_equal(node.sim.positions, node.sim.model.positions)
    assert (
        set_state(ros, S.STATE_PAUSED).result
        == srv.SetSimulationState.Response.INCORRECT_TRANSITION
    )
    assert set_state(ros, S.STATE_QUITTING).result == Result.RESULT_FEATURE_UNSUPPORTED
    assert set_state(ros, S.STATE_PLAYING).result == Result.RESULT_OK and get() == S.STATE_PLAYING
    n = len(stats)
    assert ros.spin_until(
        lambda: len(stats) > n + 3 and not stats[-1].paused and stats[-1].sim_time > 0
    )


def test_step_simulation_advances_exactly_n_steps_and_only_while_paused(ros):
    node = ros.start()
    r = call(ros, srv.StepSimulation, "step_simulation", steps=5).result
    assert r.result == Result.RESULT_OPERATION_FAILED and "paused" in r.error_message
    set_state(ros, SimulationState.STATE_PAUSED)
    for n in (1, 7, 250):
        before = node.sim.steps_taken
        t = node.sim.time
        assert (
            call(ros, srv.StepSimulation, "step_simulation", steps=n).result.result
            == Result.RESULT_OK
        )
        assert node.sim.steps_taken - before == n
        assert node.sim.time == pytest.approx(t + n * node.sim.dt, abs=1e-12)
    # from STOPPED a step goes on (and the state becomes PAUSED)
    set_state(ros, SimulationState.STATE_STOPPED)
    assert (
        call(ros, srv.StepSimulation, "step_simulation", steps=3).result.result == Result.RESULT_OK
    )
    assert node.sim.time == pytest.approx(3 * node.sim.dt)
    assert (
        call(ros, srv.GetSimulationState, "get_simulation_state").state.state
        == SimulationState.STATE_PAUSED
    )


def _send_goal(ros, client, steps, feedback):
    assert ros.spin_until(client.server_is_ready, 10)
    fut = client.send_goal_async(
        SimulateSteps.Goal(steps=steps), feedback_callback=feedback.append
    )
    assert ros.spin_until(fut.done, 10)
    handle = fut.result()
    assert handle.accepted
    return handle


def test_simulate_steps_reports_feedback_finishes_and_can_be_cancelled(ros):
    node = ros.start()
    client = ActionClient(ros.node, SimulateSteps, f"{NS}/simulate_steps")
    set_state(ros, SimulationState.STATE_PAUSED)
    feedback = []
    before = node.sim.steps_taken
    handle = _send_goal(ros, client, 120, feedback)
    res = handle.get_result_async()
    assert ros.spin_until(res.done, 20)
    assert res.result().result.result.result == Result.RESULT_OK
    assert node.sim.steps_taken - before == 120
    assert feedback and feedback[-1].feedback.completed_steps == 120
    assert feedback[-1].feedback.remaining_steps == 0
    assert all(f.feedback.completed_steps + f.feedback.remaining_steps == 120 for f in feedback)
    # a long goal, cancelled: it stops where it was, and says so
    feedback.clear()
    handle = _send_goal(ros, client, 10_000_000, feedback)
    assert ros.spin_until(lambda: len(feedback) >= 2, 10)
    cancel = handle.cancel_goal_async()
    assert ros.spin_until(cancel.done, 10)
    res = handle.get_result_async()
    assert ros.spin_until(res.done, 10)
    from action_msgs.msg import GoalStatus

    assert res.result().status == GoalStatus.STATUS_CANCELED
    assert "canceled after" in res.result().result.result.error_message
    steps = node.sim.steps_taken
    ros.spin_for(0.3)
    assert node.sim.steps_taken == steps  # nothing steps after the cancel
    # refused while playing
    set_state(ros, SimulationState.STATE_PLAYING)
    handle = _send_goal(ros, client, 10, [])
    res = handle.get_result_async()
    assert ros.spin_until(res.done, 10)
    assert res.result().result.result.result == Result.RESULT_OPERATION_FAILED


def test_entities_states_bounds_and_bad_requests(ros):
    node = ros.start(scene="drape", rows=10, cols=10, spacing=1.0 / 9)
    names = call(ros, srv.GetEntities, "get_entities").entities
    assert names[0] == "cloth" and any(n.startswith("collider/") for n in names)
    only = call(
        ros,
        srv.GetEntities,
        "get_entities",
        filters=srv.GetEntities.Request().filters.__class__(
            categories=[EntityCategory(category=EntityCategory.CATEGORY_STATIC_OBJECT)]
        ),
    ).entities
    assert only == [n for n in names if n.startswith("collider/")]
    bad = srv.GetEntities.Request()
    bad.filters.filter = "("
    r = ros.call(srv.GetEntities, f"{NS}/get_entities", bad).result
    assert r.result == Result.RESULT_OPERATION_FAILED and "regular expression" in r.error_message
    # the sphere's bounds are its box (TYPE_BOX, as GetEntityBounds.srv asks); the cloth's box
    # holds every particle
    sphere = next(n for n in names if n.startswith("collider/"))
    b = call(ros, srv.GetEntityBounds, "get_entity_bounds", entity=sphere).bounds
    c = node.sim.colliders[0]
    assert b.type == b.TYPE_BOX
    assert [b.points[0].x, b.points[0].z, b.points[1].y] == pytest.approx(
        [c.center[0] - c.radius, c.center[2] - c.radius, c.center[1] + c.radius]
    )
    # paused, so that the positions read here are the ones the answer saw (running, a tick could
    # come between the answer and the read: it did once in 20 runs)
    set_state(ros, SimulationState.STATE_PAUSED)
    b = call(ros, srv.GetEntityBounds, "get_entity_bounds", entity="cloth").bounds
    lo, hi = node.sim.positions.min(0), node.sim.positions.max(0)
    assert b.type == b.TYPE_BOX and [b.points[0].x, b.points[1].z] == pytest.approx([lo[0], hi[2]])
    set_state(ros, SimulationState.STATE_PLAYING)
    # unknown entity, NaN pose, a twist for a kinematic body: the standard's codes, with a message
    r = call(ros, srv.GetEntityState, "get_entity_state", entity="nothing").result
    assert r.result == Result.RESULT_NOT_FOUND and "cloth" in r.error_message
    req = srv.SetEntityState.Request(entity=sphere)
    req.state.pose.position.x = math.nan
    r = ros.call(srv.SetEntityState, f"{NS}/set_entity_state", req).result
    assert r.result == srv.SetEntityState.Response.INVALID_POSE and "position" in r.error_message
    req = srv.SetEntityState.Request(entity=sphere)
    req.state.pose.orientation.w = 1.0
    req.state.twist.linear.x = math.inf
    r = ros.call(srv.SetEntityState, f"{NS}/set_entity_state", req).result
    assert r.result == srv.SetEntityState.Response.INVALID_POSE and "twist" in r.error_message
    # a collider moved by set_entity_state is where get_entity_state says, and the cloth meets it
    req = srv.SetEntityState.Request(entity=sphere)
    req.state.pose.position.x, req.state.pose.position.y, req.state.pose.position.z = 0.5, 0.5, 0.3
    req.state.pose.orientation.w = 1.0
    assert (
        ros.call(srv.SetEntityState, f"{NS}/set_entity_state", req).result.result
        == Result.RESULT_OK
    )
    ros.spin_for(0.5)
    got = call(ros, srv.GetEntityState, "get_entity_state", entity=sphere).state.pose.position
    assert [got.x, got.y, got.z] == pytest.approx([0.5, 0.5, 0.3])
    assert c.signed_distance(node.sim.positions).min() >= 0.97 * node.sim.thickness


def test_set_entity_state_moves_a_gripper_and_its_wrench_follows(ros):
    from cloth_sim.srv import Grasp

    node = ros.start(scene="free_fall", rows=8, cols=8, spacing=0.05, gravity=[0.0, 0.0, 0.0])
    set_state(ros, SimulationState.STATE_PAUSED)
    req = Grasp.Request(gripper="g", radius=0.01)
    assert ros.call(Grasp, f"{NS}/grasp", req).success
    wrenches = ros.collect(WrenchStamped, f"{NS}/grippers/g/wrench")
    assert "gripper/g" in call(ros, srv.GetEntities, "get_entities").entities
    req = srv.SetEntityState.Request(entity="gripper/g")
    req.state.pose.position.x = -0.05  # pull the corner away from the cloth: the cloth pulls back
    req.state.pose.orientation.w = 1.0
    assert (
        ros.call(srv.SetEntityState, f"{NS}/set_entity_state", req).result.result
        == Result.RESULT_OK
    )
    assert (
        call(ros, srv.StepSimulation, "step_simulation", steps=20).result.result
        == Result.RESULT_OK
    )
    state = call(ros, srv.GetEntityState, "get_entity_state", entity="gripper/g").state
    assert state.pose.position.x == pytest.approx(-0.05)
    force, _ = node.sim.gripper_wrench("g")
    assert force[0] > 0  # the stretched springs pull the gripper back towards the cloth (+x)
    assert ros.spin_until(lambda: wrenches and wrenches[-1].wrench.force.x > 0, 10)


def test_reset_scopes(ros):
    node = ros.start()
    set_state(ros, SimulationState.STATE_PAUSED)
    call(ros, srv.StepSimulation, "step_simulation", steps=100)
    moved = node.sim.positions.copy()
    R = srv.ResetSimulation.Request
    assert (
        call(ros, srv.ResetSimulation, "reset_simulation", scope=R.SCOPE_TIME).result.result
        == Result.RESULT_OK
    )
    assert node.sim.time == 0.0
    np.testing.assert_array_equal(node.sim.positions, moved)  # time only
    call(ros, srv.StepSimulation, "step_simulation", steps=10)
    assert (
        call(ros, srv.ResetSimulation, "reset_simulation", scope=R.SCOPE_STATE).result.result
        == Result.RESULT_OK
    )
    assert node.sim.time == pytest.approx(10 * node.sim.dt)  # state only
    np.testing.assert_array_equal(node.sim.positions, node.sim.model.positions)
    assert node.paused  # a reset keeps the simulation's state
    r = call(ros, srv.ResetSimulation, "reset_simulation", scope=R.SCOPE_SPAWNED).result
    assert r.result == Result.RESULT_OK  # nothing spawned: nothing to remove
    call(ros, srv.StepSimulation, "step_simulation", steps=10)
    assert (
        call(ros, srv.ResetSimulation, "reset_simulation", scope=R.SCOPE_DEFAULT).result.result
        == Result.RESULT_OK
    )
    assert node.sim.time == 0.0


def test_frames_reach_tf_static_and_tf(ros):
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from tf2_msgs.msg import TFMessage

    node = ros.start(scene="drape", rows=10, cols=10, spacing=1.0 / 9)
    static, dynamic = [], []
    qos = QoSProfile(
        depth=1,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
        reliability=ReliabilityPolicy.RELIABLE,
    )
    ros.node.create_subscription(TFMessage, "/tf_static", static.append, qos)  # a late joiner
    ros.node.create_subscription(TFMessage, "/tf", dynamic.append, 10)
    assert ros.spin_until(lambda: static and dynamic, 10)
    (t,) = static[-1].transforms
    assert (t.header.frame_id, t.child_frame_id) == (
        "world",
        "cloth",
    ) and t.transform.rotation.w == 1.0
    frames = {f.child_frame_id: f for f in dynamic[-1].transforms}
    c = node.sim.colliders[0]
    f = frames[f"cloth/collider/{c.name}"]
    assert f.header.frame_id == "cloth"
    assert [
        f.transform.translation.x,
        f.transform.translation.y,
        f.transform.translation.z,
    ] == pytest.approx(c.position.tolist())
    # a new frame_id moves the static frame with it
    assert all(
        r.successful
        for r in ros.set_params("/cloth_sim", {"frame_id": "sheet", "world_frame_id": "map"})
    )
    assert ros.spin_until(lambda: static[-1].transforms[0].child_frame_id == "sheet", 10)
    assert static[-1].transforms[0].header.frame_id == "map"


def test_a_spawned_sphere_is_hit_by_the_cloth_and_a_deleted_one_no_longer_is(ros):
    node = ros.start(scene="free_fall", rows=10, cols=10, spacing=0.05)
    set_state(ros, SimulationState.STATE_PAUSED)
    spawnables = call(ros, srv.GetSpawnables, "get_spawnables").spawnables
    assert {s.uri.split("?")[0] for s in spawnables} == {
        "cloth_sim://sphere",
        "cloth_sim://box",
        "cloth_sim://capsule",
        "cloth_sim://plane",
    }
    centre = node.sim.positions.mean(axis=0) - [0.0, 0.0, 0.15]
    req = srv.SpawnEntity.Request(name="ball", uri="cloth_sim://sphere?radius=0.08&friction=0.5")
    (
        req.initial_pose.pose.position.x,
        req.initial_pose.pose.position.y,
        req.initial_pose.pose.position.z,
    ) = centre
    req.initial_pose.pose.orientation.w = 1.0
    r = ros.call(srv.SpawnEntity, f"{NS}/spawn_entity", req)
    assert r.result.result == Result.RESULT_OK and r.entity_name == "collider/ball"
    assert "collider/ball" in call(ros, srv.GetEntities, "get_entities").entities
    ball = node.sim.colliders[-1]
    call(ros, srv.StepSimulation, "step_simulation", steps=400)
    # the cloth came down on it and rests on it at the thickness, above its centre
    assert ball.signed_distance(node.sim.positions).min() >= 0.97 * node.sim.thickness
    assert node.sim.positions[:, 2].max() > centre[2]
    # the same name again: refused unless renaming is allowed; bad resources get the standard's
    # codes
    r = ros.call(srv.SpawnEntity, f"{NS}/spawn_entity", req)
    assert r.result.result == srv.SpawnEntity.Response.NAME_NOT_UNIQUE
    req.allow_renaming = True
    req.initial_pose.pose.position.x += 5.0
    assert ros.call(srv.SpawnEntity, f"{NS}/spawn_entity", req).entity_name == "collider/ball_1"
    R = srv.SpawnEntity.Response
    for fields, code, words in [
        ({"uri": "model://table"}, R.UNSUPPORTED_FORMAT, "cloth_sim://<shape>"),
        ({"uri": "cloth_sim://sphere?radius=-1"}, R.RESOURCE_PARSE_ERROR, "radius"),
        (
            {"resource_string": "{type: sphere, radius: 0.05, colour: red}"},
            R.RESOURCE_PARSE_ERROR,
            "colour",
        ),
        ({}, R.NO_RESOURCE, "uri"),
        ({"uri": "cloth_sim://box", "name": "9lives"}, R.NAME_INVALID, "name"),
    ]:
        r = ros.call(
            srv.SpawnEntity, f"{NS}/spawn_entity", srv.SpawnEntity.Request(**fields)
        ).result
        assert r.result == code and words in r.error_message, (fields, r.error_message)
    bad = srv.SpawnEntity.Request(name="nan_ball", uri="cloth_sim://sphere?radius=0.05")
    bad.initial_pose.pose.position.x = math.nan
    r = ros.call(srv.SpawnEntity, f"{NS}/spawn_entity", bad).result
    assert r.result == R.INVALID_POSE and "initial_pose.pose.position" in r.error_message
    # deleted: the cloth falls past where it was
    assert (
        call(ros, srv.DeleteEntity, "delete_entity", entity="collider/ball").result.result
        == Result.RESULT_OK
    )
    assert "collider/ball" not in call(ros, srv.GetEntities, "get_entities").entities
    call(ros, srv.StepSimulation, "step_simulation", steps=400)
    assert node.sim.positions[:, 2].max() < centre[2] - 0.08
    assert (
        call(ros, srv.DeleteEntity, "delete_entity", entity="cloth").result.result
        == Result.RESULT_OPERATION_FAILED
    )
    # resetting the spawned scope removes what is left of them
    R2 = srv.ResetSimulation.Request
    assert (
        call(ros, srv.ResetSimulation, "reset_simulation", scope=R2.SCOPE_SPAWNED).result.result
        == Result.RESULT_OK
    )
    assert not [
        n for n in call(ros, srv.GetEntities, "get_entities").entities if n.startswith("collider/")
    ]


def test_a_node_process_is_driven_through_the_standard_from_another_process():
    """The same calls a Gazebo harness makes, to a cloth_sim_node process: features, pause, exactly
    n steps, and the state they leave."""
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from ros_helpers import answer
    from test_node import next_domain, node_env

    domain = next_domain()
    exe = Path(sys.executable).parent / "cloth_sim_node"
    proc = subprocess.Popen(
        [str(exe), "--ros-args", "-p", "rows:=12", "-p", "cols:=12", "-p", "spacing:=0.09"],
        env=node_env(domain),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain)
    client = rclpy.create_node("harness", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(client)

    from cloth_sim.srv import Step

    kinds = {
        "get_simulator_features": srv.GetSimulatorFeatures,
        "set_simulation_state": srv.SetSimulationState,
        "reset_simulation": srv.ResetSimulation,
        "step_simulation": srv.StepSimulation,
        "step": Step,
        "get_simulation_state": srv.GetSimulationState,
    }
    # every client made and discovered before the first request: a response to a client made a
    # moment before can be lost under load (ros_helpers.answer), which one failure in 20 runs of
    # the ROS tests was (get_simulator_features, 30 s without an answer)
    clients = {name: client.create_client(kind, f"{NS}/{name}") for name, kind in kinds.items()}
    end = time.monotonic() + 60
    while not all(c.service_is_ready() for c in clients.values()) and time.monotonic() < end:
        ex.spin_once(timeout_sec=0.05)

    def call(name, repeatable=True, **fields):
        """The node's response; a request that may be repeated (all but step_simulation's) is
        sent again after 5 s without one."""
        assert clients[name].service_is_ready(), f"{name} not available after 60 s"
        response = answer(
            ex,
            clients[name],
            kinds[name].Request(**fields),
            time.monotonic() + 30,
            resend_every=5.0 if repeatable else None,
        )
        assert response is not None, f"{name} did not answer"
        return response

    try:
        assert (
            SimulatorFeatures.STEP_SIMULATION_MULTIPLE
            in call("get_simulator_features").features.features
        )
        assert (
            call(
                "set_simulation_state",
                state=SimulationState(state=SimulationState.STATE_PAUSED),
            ).result.result
            == Result.RESULT_OK
        )
        call("reset_simulation", scope=srv.ResetSimulation.Request.SCOPE_TIME)
        assert (
            call("step_simulation", repeatable=False, steps=250).result.result == Result.RESULT_OK
        )
        # ~/step with 0 steps reports the simulated time: exactly the 250 steps of dt = 1 ms
        assert call("step", steps=0).sim_time == pytest.approx(0.25, abs=1e-9)
        state = call("get_simulation_state").state.state
        assert state == SimulationState.STATE_PAUSED
    finally:
        ex.shutdown()
        client.destroy_node()
        rclpy.shutdown(context=ctx)
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=20)
    assert proc.returncode == 0, out


def test_a_twist_keeps_a_kinematic_collider_moving_and_drags_what_rests_on_it(ros):
    """set_entity_state with a twist: the table moves at that velocity, step by step (exactly
    v·n·dt after n steps), turns at its angular velocity, reports the twist, and carries the cloth
    lying on it by friction; a zero twist stops it."""
    node = ros.start(scene="table", rows=10, cols=10, spacing=0.06, size=[0.0, 0.0])
    set_state(ros, SimulationState.STATE_PAUSED)
    call(ros, srv.StepSimulation, "step_simulation", steps=800)  # the cloth settles on the table
    table = node.sim.colliders[0]
    p0, q0 = table.position.copy(), table.orientation.copy()
    on_table = table.signed_distance(node.sim.positions) < 2 * node.sim.thickness
    x0 = node.sim.positions[on_table].mean(axis=0)
    req = srv.SetEntityState.Request(entity=f"collider/{table.name}")
    (req.state.pose.position.x, req.state.pose.position.y, req.state.pose.position.z) = p0
    (
        req.state.pose.orientation.w,
        req.state.pose.orientation.x,
        req.state.pose.orientation.y,
        req.state.pose.orientation.z,
    ) = q0
    req.state.twist.linear.y = 0.2
    # a collider is a STATIC_OBJECT: the standard refuses it a twist, and nothing changes
    r = ros.call(srv.SetEntityState, f"{NS}/set_entity_state", req).result
    assert r.result == Result.RESULT_OPERATION_FAILED and "DYNAMIC_OBJECT" in r.error_message
    call(ros, srv.StepSimulation, "step_simulation", steps=10)
    np.testing.assert_array_equal(table.position, p0)
    # made a DYNAMIC_OBJECT (a kinematic obstacle), it takes the twist
    info = EntityInfo(category=EntityCategory(category=EntityCategory.CATEGORY_DYNAMIC_OBJECT))
    assert (
        call(
            ros, srv.SetEntityInfo, "set_entity_info", entity=f"collider/{table.name}", info=info
        ).result.result
        == Result.RESULT_OK
    )
    assert (
        ros.call(srv.SetEntityState, f"{NS}/set_entity_state", req).result.result
        == Result.RESULT_OK
    )
    state = call(
        ros, srv.GetEntityState, "get_entity_state", entity=f"collider/{table.name}"
    ).state
    assert state.twist.linear.y == 0.2
    n = 500
    call(ros, srv.StepSimulation, "step_simulation", steps=n)
    assert table.position == pytest.approx(p0 + [0.0, 0.2 * n * node.sim.dt, 0.0], abs=1e-12)
    # what rests on it went along (friction): most of the table's 0.1 m
    moved = node.sim.positions[on_table].mean(axis=0) - x0
    assert moved[1] > 0.05
    req.state.twist.linear.y = 0.0
    (req.state.pose.position.x, req.state.pose.position.y, req.state.pose.position.z) = (
        table.position
    )
    ros.call(srv.SetEntityState, f"{NS}/set_entity_state", req)
    p1 = table.position.copy()
    call(ros, srv.StepSimulation, "step_simulation", steps=50)
    np.testing.assert_array_equal(table.position, p1)
    # an angular velocity turns it: a quarter turn about z in pi/2 s
    req.state.twist.angular.z = 1.0
    ros.call(srv.SetEntityState, f"{NS}/set_entity_state", req)
    call(ros, srv.StepSimulation, "step_simulation", steps=int(round(math.pi / 2 / node.sim.dt)))
    angle = 2 * math.atan2(table.orientation[3], table.orientation[0]) - 2 * math.atan2(
        q0[3], q0[0]
    )
    assert angle == pytest.approx(math.pi / 2, abs=2e-3)
