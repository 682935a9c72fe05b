"""The ROS 2 adapter: the node (:mod:`.node`), its parameters (:mod:`.params`), its messages
(:mod:`.messages`). The only part of cloth_sim that imports rclpy or ROS messages.

:func:`main` is the ``cloth_sim_node`` entry point. It installs the SIGINT/SIGTERM handlers before
importing rclpy, numpy or the simulator (about a second), so a signal at any moment of the
process's life ends it with exit status 0 and no traceback.
"""

from __future__ import annotations

import signal


class StopRequest:
    """Records SIGINT/SIGTERM; the node's spin loop checks it. A handler that only records the
    signal cannot interrupt the node half-way through a tick or ``destroy_node`` (rclpy's own
    handlers shut the context down under a running tick; Python's default raises
    KeyboardInterrupt wherever the main thread is)."""

    def __init__(self):
        self.signals: list[int] = []

    def __call__(self, signum, frame):
        self.signals.append(signum)

    def __bool__(self):
        return bool(self.signals)

    def install(self) -> "StopRequest":
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self)
        return self


def main(argv=None) -> int:
    """``cloth_sim_node`` (``ros2 run cloth_sim cloth_sim_node``): see :func:`.node.run`.

    Once the node is down, further SIGINT/SIGTERM are ignored: Python's finalisation puts the
    default handlers back, and a second signal landing there (``ros2 launch`` sends two on Ctrl-C)
    would end the process with status −2 instead of 0."""
    stop = StopRequest().install()
    try:
        from .node import run

        return run(argv, stop)
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_IGN)
