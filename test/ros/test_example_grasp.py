"""examples/grasp_node.py, the docs' node example, against a live node: it grasps, lifts, releases
and steps in lockstep through the node's services and topics."""

import subprocess
import sys
from pathlib import Path

from ros_helpers import end_node, next_domain, node_env, start_node

ROOT = Path(__file__).resolve().parents[2]


def test_the_grasp_example_drives_the_node():
    domain = next_domain()
    node = start_node(domain)
    try:
        r = subprocess.run(
            [sys.executable, str(ROOT / "examples" / "grasp_node.py"), "--quick"],
            env=node_env(domain),
            capture_output=True,
            text=True,
            timeout=180,
        )
    finally:
        node.terminate()
        end_node(node)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "grasp: True" in r.stdout and "release: True" in r.stdout
    assert "pull on the gripper" in r.stdout and "stepped to t =" in r.stdout
