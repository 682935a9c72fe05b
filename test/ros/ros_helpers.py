"""What the node's tests share: a DDS domain per test (kept apart from every other test process's),
the environment of a node process, and starting and ending one."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
#: pytest-xdist's workers each take their own band of 40 domains (20–59, 60–99, …); within it a
#: process starts at an offset from its pid, so that two runs on one machine rarely meet
_BAND = 20 + 40 * (int(os.environ.get("PYTEST_XDIST_WORKER", "gw0")[2:] or 0) % 5)
_NEXT = [os.getpid() % 40]


def next_domain() -> int:
    """A DDS domain id no other test of this process uses at the same time."""
    _NEXT[0] = (_NEXT[0] + 1) % 40
    return _BAND + _NEXT[0]


def node_env(domain: int) -> dict:
    env = dict(
        os.environ,
        ROS_DOMAIN_ID=str(domain),
        ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
        ROS_LOG_DIR=str(ROOT / ".ros_log"),
        PYTHONUNBUFFERED="1",
    )
    return env


def caught_signals(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("SigCgt:"):
            return int(line.split()[1], 16)
    return 0


def start_node(domain, *extra, ignore_sigint=False):
    exe = Path(sys.executable).parent / "cloth_sim_node"
    pre = (lambda: signal.signal(signal.SIGINT, signal.SIG_IGN)) if ignore_sigint else None
    proc = subprocess.Popen(
        [str(exe), "--ros-args", "--params-file", str(ROOT / "config" / "cloth_sim.yaml"), *extra],
        env=node_env(domain),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        preexec_fn=pre,
    )
    # the node's own handlers are in place once it catches SIGTERM (Python catches SIGINT from
    # start-up; nothing catches SIGTERM before cloth_sim.ros.main): the race this test covers
    # starts there. Before it, a signal meets Python's start-up and the ROS wheels' re-exec.
    end = time.monotonic() + 20
    while time.monotonic() < end and not caught_signals(proc.pid) & (1 << (signal.SIGTERM - 1)):
        time.sleep(0.005)
    return proc


def answer(executor, client, request, deadline: float, resend_every: float | None = None):
    """``client``'s response to ``request``, spinning ``executor`` until the monotonic
    ``deadline``; ``None`` when none came. Under load DDS can lose the response to a client made a
    moment before: the server waits a bounded time (rmw_fastrtps: its response writer's
    max_blocking_time, 100 ms) for the new client's response reader to be discovered, then drops
    the response (ros2/rmw_fastrtps#390). A request that may be repeated is sent again every
    ``resend_every`` s until a response comes."""
    future = client.call_async(request)
    sent = time.monotonic()
    while not future.done() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
        if (
            resend_every is not None
            and not future.done()
            and time.monotonic() > sent + resend_every
        ):
            client.remove_pending_request(future)
            future = client.call_async(request)
            sent = time.monotonic()
    return future.result() if future.done() else None


def end_node(proc, timeout=30):
    out, _ = proc.communicate(timeout=timeout)
    return proc.returncode, out


def run_example(name: str, *node_args) -> subprocess.CompletedProcess:
    """``examples/<name> --quick`` against a node started with ``node_args`` on a domain of its
    own; the node is ended whatever the example did."""
    domain = next_domain()
    node = start_node(domain, *node_args)
    try:
        return subprocess.run(
            [sys.executable, str(ROOT / "examples" / name), "--quick"],
            env=node_env(domain),
            capture_output=True,
            text=True,
            timeout=180,
        )
    finally:
        node.terminate()
        end_node(node)
