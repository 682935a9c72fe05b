"""Write throughput of ``cloth-sim record`` against a running node.

``cloth-sim bench record --size 64 --rate 60 --seconds 10`` starts ``cloth_sim_node`` in its own
process (N×N cloth, the given publish rate, strain limit off so the node itself keeps the rate on 2
cores), records ``~/points`` and ``~/stats`` in this process for the given time, and prints
messages/s, MB/s of message data and on disk, the recorder's CPU load, and how many messages the
node sent in the recorded window against how many were written. "Sent" is read from the node's own
tick sequence: consecutive ``~/stats`` messages advance ``sim_time`` by exactly ``steps·dt``, so a
tick missing from the bag shows as a jump; each tick sends one cloud and one stats message.
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import rclpy
from rclpy.serialization import deserialize_message
from rclpy.signals import SignalHandlerOptions

from ..bag.record import Recorder
from ..bag.store import iter_messages


def measure(size: int, rate: float, seconds: float, domain: int) -> dict:
    from cloth_sim.msg import Stats

    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    exe = Path(sys.executable).parent / "cloth_sim_node"
    node = subprocess.Popen(
        [
            str(exe),
            "--ros-args",
            "-p",
            f"rows:={size}",
            "-p",
            f"cols:={size}",
            "-p",
            f"spacing:={1.0 / (size - 1)}",
            "-p",
            f"publish_rate:={rate}",
            "-p",
            "strain_limit:=0.0",
        ],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.STDOUT,
    )
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
    try:
        with tempfile.TemporaryDirectory() as tmp:
            bag = Path(tmp) / "throughput"
            rec = Recorder(
                bag, ["/cloth_sim/points", "/cloth_sim/stats"], context=ctx, log=lambda s: None
            )
            end = time.monotonic() + 30
            while len(rec.subscribed) < 2 and time.monotonic() < end:  # discovery, node start-up
                rec.executor.spin_once(timeout_sec=0.05)
            rec.duration = seconds
            cpu0 = time.process_time()
            r = rec.run()
            cpu = time.process_time() - cpu0
            stats, clouds = [], 0
            for topic, msg in iter_messages(bag):
                if topic.name == "/cloth_sim/stats":
                    stats.append(deserialize_message(bytes(msg.data), Stats))
                else:
                    clouds += 1
        ticks = len(stats)
        for a, b in zip(stats, stats[1:]):
            ticks += max(0, round((b.sim_time - a.sim_time) / b.dt) // max(b.steps, 1) - 1)
    finally:
        node.terminate()
        node.wait(20)
        rclpy.try_shutdown(context=ctx)
    return {
        "N": size,
        "rate": rate,
        "seconds": r["seconds"],
        "messages": r["messages"],
        "msg_per_s": r["messages"] / r["seconds"],
        "MB_per_s": r["bytes"] / 1e6 / r["seconds"],
        "disk_MB_per_s": r["file_bytes"] / 1e6 / r["seconds"],
        "cpu": cpu / r["seconds"],
        "ticks_sent": ticks,
        "stats_written": len(stats),
        "clouds_written": clouds,
    }


def print_record_table(size: int, rate: float, seconds: float) -> None:
    domain = int(os.environ.get("ROS_DOMAIN_ID", "0"))
    m = measure(size, rate, seconds, domain)
    print(
        f"# cloth-sim record vs cloth_sim_node, {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} cores, N={size}, {rate:g} Hz, {m['seconds']:.1f} s"
    )
    print(
        "| N | rate (Hz) | messages/s | MB/s (messages) | MB/s (on disk) | recorder CPU | "
        "ticks sent | stats written | clouds written |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    print(
        f"| {m['N']} | {m['rate']:g} | {m['msg_per_s']:.1f} | {m['MB_per_s']:.2f} | "
        f"{m['disk_MB_per_s']:.2f} | "
        f"{100 * m['cpu']:.0f} % | {m['ticks_sent']} | {m['stats_written']} | "
        f"{m['clouds_written']} |"
    )
