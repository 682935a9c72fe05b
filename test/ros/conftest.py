"""The ``ros`` fixture: an rclpy context on a fresh DDS domain, an executor, a client node, and
nodes started in-process on it; torn down after each test."""

import os
import time

import pytest

rclpy = pytest.importorskip("rclpy", reason="ROS 2 wheels are installed by `make`")

from rcl_interfaces.srv import SetParameters, SetParametersAtomically  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from ros_helpers import next_domain  # noqa: E402

from cloth_sim.ros.node import ClothSimNode  # noqa: E402


@pytest.fixture
def ros():
    """An rclpy context on a fresh domain, an executor, and a client node; torn down after."""
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=next_domain())
    ex = SingleThreadedExecutor(context=ctx)
    client = rclpy.create_node("cloth_sim_test", context=ctx)
    ex.add_node(client)

    class Ros:
        context, executor, node = ctx, ex, client
        nodes = []

        def start(self, namespace="", **overrides):
            # the per-family sheet the parameter tests change (the default, hanging, is cotton:
            # its springs are the fabric's; test_node.py's own tests start it)
            overrides.setdefault("scene", "hanging_provot")
            overrides.setdefault("rows", 12)
            overrides.setdefault("cols", 12)
            overrides.setdefault("spacing", 1.0 / 11)
            node = ClothSimNode(
                context=ctx,
                namespace=namespace,
                parameter_overrides=[Parameter(k, value=v) for k, v in overrides.items()],
            )
            ex.add_node(node)
            self.nodes.append(node)
            return node

        def spin_until(self, cond, timeout=10.0):
            end = time.monotonic() + timeout
            while time.monotonic() < end:
                if cond():
                    return True
                ex.spin_once(timeout_sec=0.02)
            return cond()

        def spin_for(self, seconds):
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                ex.spin_once(timeout_sec=0.02)

        def collect(self, msg_type, topic):
            got = []
            self.node.create_subscription(msg_type, topic, got.append, 50)
            return got

        def call(self, srv_type, name, request, timeout=10.0):
            cli = self.node.create_client(srv_type, name)
            assert self.spin_until(cli.service_is_ready, timeout), f"{name} not available"
            fut = cli.call_async(request)
            assert self.spin_until(fut.done, timeout), f"{name} did not answer"
            return fut.result()

        def set_params(self, node_name, params, atomically=False):
            """Set parameters through the standard parameter services; returns the results."""
            msgs = [Parameter(k, value=v).to_parameter_msg() for k, v in params.items()]
            if atomically:
                req = SetParametersAtomically.Request(parameters=msgs)
                return [
                    self.call(
                        SetParametersAtomically, f"{node_name}/set_parameters_atomically", req
                    ).result
                ]
            req = SetParameters.Request(parameters=msgs)
            return self.call(SetParameters, f"{node_name}/set_parameters", req).results

    r = Ros()
    yield r
    for n in r.nodes:
        ex.remove_node(n)
        n.destroy_node()
    # a test's action clients: destroy_node leaves them, and they keep the node in the graph
    for w in list(client.waitables):
        if hasattr(w, "destroy"):
            w.destroy()
    client.destroy_node()
    ex.shutdown()
    rclpy.shutdown(context=ctx)
