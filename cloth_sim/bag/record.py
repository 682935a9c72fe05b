"""``cloth-sim record``: subscribe raw (no deserialisation) and write a rosbag2 bag, as ``ros2 bag
record``.

The main thread spins rclpy and only queues (topic, bytes, times) from each callback; a writer
thread owns the MCAP writer (Zstd compression releases the GIL), so compression never delays the
subscriptions. Topics are looked up every ``poll`` seconds, so topics that appear after the start
are recorded too. A subscription's QoS is adapted to its publishers' offers as rosbag2 does
(reliable only if every publisher is; transient-local only if every publisher is), and the offers
are stored as the channel's ``offered_qos_profiles``.
"""

from __future__ import annotations

import importlib
import queue
import signal
import threading
import time
from pathlib import Path

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.expand_topic_name import expand_topic_name
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.validate_full_topic_name import validate_full_topic_name

from .store import BagError, BagWriter, message_definition, time_dict

DEFAULT_TOPICS = ["/cloth_sim/points", "/cloth_sim/stats", "/diagnostics", "/parameter_events"]
SUBSCRIPTION_DEPTH = 1000


def normalise_topics(topics: list[str]) -> list[str]:
    """Fully qualified names; BagError naming the first invalid one."""
    out = []
    for name in topics:
        try:
            full = expand_topic_name(name, "cloth_sim_recorder", "/")
            validate_full_topic_name(full)
        except Exception as e:  # rclpy raises InvalidTopicNameException, ValueError, RCLError, …
            reason = str(e).splitlines()[0] if str(e) else type(e).__name__
            raise BagError(f"invalid topic name {name!r}: {reason}") from None
        out.append(full)
    return out


def qos_dict(q) -> dict:
    """An rclpy QoSProfile as metadata version 9 writes it."""

    def enum(v):
        return v.name.lower() if hasattr(v, "name") else str(v)

    return {
        "history": enum(q.history),
        "depth": int(q.depth),
        "reliability": enum(q.reliability),
        "durability": enum(q.durability),
        "deadline": time_dict(q.deadline.nanoseconds),
        "lifespan": time_dict(q.lifespan.nanoseconds),
        "liveliness": enum(q.liveliness),
        "liveliness_lease_duration": time_dict(q.liveliness_lease_duration.nanoseconds),
        "avoid_ros_namespace_conventions": bool(q.avoid_ros_namespace_conventions),
    }


def adapted_qos(offers) -> QoSProfile:
    reliable = bool(offers) and all(o.reliability == ReliabilityPolicy.RELIABLE for o in offers)
    latched = bool(offers) and all(
        o.durability == DurabilityPolicy.TRANSIENT_LOCAL for o in offers
    )
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=SUBSCRIPTION_DEPTH,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


def message_class(type_name: str):
    pkg, sub, name = type_name.split("/")
    return getattr(importlib.import_module(f"{pkg}.{sub}"), name)


class Recorder:
    """Records ``topics`` (or every topic with ``topics=None``) into the bag at ``path``."""

    def __init__(
        self,
        path,
        topics: list[str] | None = None,
        *,
        overwrite: bool = False,
        duration: float | None = None,
        max_messages: int | None = None,
        poll: float = 0.1,
        context=None,
        log=print,
    ):
        self.wanted = None if topics is None else normalise_topics(topics)
        self.duration, self.max_messages, self.log = duration, max_messages, log
        self.writer = BagWriter(path, overwrite=overwrite)
        self.node = rclpy.create_node(
            "cloth_sim_recorder", context=context, start_parameter_services=False
        )
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.subscribed: dict[str, str] = {}
        self.skipped: set[str] = set()
        self.received = 0
        self.stop_requested = False
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._channels: dict[str, int] = {}
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._write_loop, name="bag-writer", daemon=True)
        self._thread.start()
        self.node.create_timer(poll, self.discover)

    # -------------------------------------------------------------------------------- discovery
    def discover(self) -> None:
        for name, types in self.node.get_topic_names_and_types():
            if name in self.subscribed or name in self.skipped:
                continue
            if self.wanted is None:
                if name == "/rosout":
                    continue
            elif name not in self.wanted:
                continue
            infos = self.node.get_publishers_info_by_topic(name)
            offers = [i.qos_profile for i in infos]
            if not offers:
                continue  # only subscribers so far: nothing to adapt to
            type_name = types[0]
            try:
                cls = message_class(type_name)
                definition = message_definition(type_name)
            except (ImportError, AttributeError, ValueError, BagError) as e:
                self.skipped.add(name)
                self.log(
                    f"warning: not recording {name}: type {type_name} is not available here ({e})"
                )
                continue
            digest = str(infos[0].topic_type_hash)
            self._queue.put(
                ("topic", name, type_name, [qos_dict(o) for o in offers], digest, definition)
            )
            self.node.create_subscription(
                cls, name, self._callback(name), adapted_qos(offers), raw=True
            )
            self.subscribed[name] = type_name
            self.log(f"recording {name} [{type_name}]")

    def _callback(self, name: str):
        clock = self.node.get_clock()

        def on_message(data: bytes, info) -> None:
            if self.max_messages is not None and self.received >= self.max_messages:
                self.stop_requested = True
                return
            log_time = clock.now().nanoseconds
            self.received += 1
            self._queue.put(
                (
                    "msg",
                    name,
                    log_time,
                    data,
                    info.get("source_timestamp") or log_time,
                    info.get("publication_sequence_number") or 0,
                )
            )
            if self.max_messages is not None and self.received >= self.max_messages:
                self.stop_requested = True

        return on_message

    # ----------------------------------------------------------------------------------- writing
    def _write_loop(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            try:
                if item[0] == "msg":
                    _, name, log_time, data, pub_time, seq = item
                    self.writer.write(
                        self._channels[name], log_time, data, pub_time, seq & 0xFFFFFFFF
                    )
                else:
                    _, name, type_name, offers, digest, definition = item
                    self._channels[name] = self.writer.add_topic(
                        name, type_name, offers, digest, definition
                    )
            except BaseException as e:  # disk full, …: stop recording, keep what is written
                self._error = e
                self.stop_requested = True
                return

    # ---------------------------------------------------------------------------------- running
    def run(self) -> dict:
        """Spin until stopped (signal, --duration, --max-messages or a write error); close the
        bag."""
        start = time.monotonic()
        self.discover()
        try:
            while not self.stop_requested:
                if self.duration is not None and time.monotonic() - start >= self.duration:
                    break
                self.executor.spin_once(timeout_sec=0.05)
        finally:
            wall = time.monotonic() - start
            self.node.destroy_node()
            self.executor.shutdown()
            self._queue.put(None)
            self._thread.join()
            meta = self.writer.close()
        if self._error is not None:
            raise BagError(
                f"writing {self.writer.file_path} failed: {self._error}; "
                f"the {self.writer.message_count} messages before it are in the bag"
            )
        missing = (
            [] if self.wanted is None else [t for t in self.wanted if t not in self.subscribed]
        )
        return {
            "messages": self.writer.message_count,
            "received": self.received,
            "bytes": self.writer.bytes_written,
            "file_bytes": self.writer.file_path.stat().st_size,
            "seconds": wall,
            "topics": len(self.subscribed),
            "missing": missing,
            "metadata": meta,
        }


def main(args) -> int:
    """``cloth-sim record``: returns the exit status."""
    topics = None if args.all else (args.topics or DEFAULT_TOPICS)
    if topics is not None:
        normalise_topics(topics)  # refuse a bad name before creating anything
    if args.duration is not None and not args.duration > 0:
        raise BagError(f"--duration must be > 0 s, got {args.duration}")
    if args.max_messages is not None and args.max_messages < 1:
        raise BagError(f"--max-messages must be ≥ 1, got {args.max_messages}")
    out = Path(args.output) if args.output else Path(time.strftime("rosbag2_%Y_%m_%d-%H_%M_%S"))
    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    recorder = None
    try:
        recorder = Recorder(
            out,
            topics,
            overwrite=args.overwrite,
            duration=args.duration,
            max_messages=args.max_messages,
            context=context,
        )

        def stop(signum, frame):
            recorder.stop_requested = True

        signal.signal(signal.SIGINT, stop)
        signal.signal(signal.SIGTERM, stop)
        print(f"recording to {out} (Ctrl-C to stop)", flush=True)
        r = recorder.run()
    finally:
        rclpy.try_shutdown(context=context)
    rate = r["messages"] / r["seconds"] if r["seconds"] > 0 else 0.0
    print(
        f"recorded {r['messages']} messages on {r['topics']} topics in {r['seconds']:.2f} s "
        f"({rate:.1f} msg/s, {r['bytes'] / 1e6 / max(r['seconds'], 1e-9):.2f} MB/s of messages, "
        f"{r['file_bytes'] / 1e6:.2f} MB on disk) to {out}",
        flush=True,
    )
    for t in r["missing"]:
        print(
            f"warning: {t} was never published while recording; it is not in the bag", flush=True
        )
    return 0
