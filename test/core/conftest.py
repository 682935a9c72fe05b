"""The core's tests run without ROS: in a run of this folder alone (``make test`` runs it so, and
each pytest-xdist worker of it), a test after which rclpy is imported fails."""

import sys

import pytest


def _core_only(session) -> bool:
    return bool(session.items) and all("test/core/" in str(i.path) for i in session.items)


@pytest.fixture(autouse=True)
def _without_ros(request):
    yield
    if "rclpy" in sys.modules and _core_only(request.session):
        pytest.fail("cloth_sim's core imported rclpy: the core must not need ROS", pytrace=False)
