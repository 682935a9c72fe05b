"""examples/grasp_node.py, the docs' node example, against a live node: it grasps, lifts, releases
and steps in lockstep through the node's services and topics."""

from ros_helpers import run_example


def test_the_grasp_example_drives_the_node():
    r = run_example("grasp_node.py")
    assert r.returncode == 0, r.stderr[-3000:]
    assert "grasp: True" in r.stdout and "release: True" in r.stdout
    assert "pull on the gripper" in r.stdout and "stepped to t =" in r.stdout
