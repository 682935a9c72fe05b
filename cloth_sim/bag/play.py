"""``cloth-sim play``: publish a bag's recorded bytes with their original relative timing and QoS,
as ``ros2 bag play`` does.

Message i is published at wall time ``start + (log_time_i − log_time_first − offset) / rate``; the
schedule is absolute, so sleeping late for one message does not shift the ones after it. Each topic
gets one publisher with the QoS its recorded publishers offered (the first offer; an unknown or
system-default history becomes keep-last with the recorded depth, at least 10).
"""

from __future__ import annotations

import signal
import time

import rclpy
from rclpy.duration import Duration
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from rclpy.signals import SignalHandlerOptions

from .record import message_class
from .store import INFINITE_NS, BagError, bag_info, iter_messages, parse_qos_profiles, time_ns


def qos_from_offer(offer: dict | None) -> QoSProfile:
    """An rclpy QoSProfile from one recorded offer (metadata v9 strings or older integer enums)."""
    if not offer:
        return QoSProfile(depth=10)

    def policy(enum, key, default):
        v = offer.get(key)
        try:
            return enum(v) if isinstance(v, int) else enum[str(v).upper()]
        except (KeyError, ValueError):
            return default

    history = policy(HistoryPolicy, "history", HistoryPolicy.KEEP_LAST)
    depth = int(offer.get("depth") or 0)
    if history not in (HistoryPolicy.KEEP_LAST, HistoryPolicy.KEEP_ALL):
        history = HistoryPolicy.KEEP_LAST
    if history == HistoryPolicy.KEEP_LAST:
        depth = max(depth, 10)
    q = QoSProfile(
        history=history,
        depth=depth,
        reliability=policy(ReliabilityPolicy, "reliability", ReliabilityPolicy.RELIABLE),
        durability=policy(DurabilityPolicy, "durability", DurabilityPolicy.VOLATILE),
        liveliness=policy(LivelinessPolicy, "liveliness", LivelinessPolicy.AUTOMATIC),
    )
    for key in ("deadline", "lifespan", "liveliness_lease_duration"):
        ns = time_ns(offer.get(key))
        if 0 < ns < INFINITE_NS:
            setattr(q, key, Duration(nanoseconds=ns))
    return q


class Player:
    def __init__(
        self,
        path,
        *,
        rate: float = 1.0,
        loop: bool = False,
        topics: list[str] | None = None,
        start_offset: float = 0.0,
        ack_timeout: float = 5.0,
        context=None,
        log=print,
    ):
        if not 0 < rate < float("inf"):  # (also false for NaN)
            raise BagError(f"--rate must be a finite number > 0, got {rate}")
        if not start_offset >= 0:
            raise BagError(f"--start-offset must be ≥ 0 s, got {start_offset}")
        self.info = bag_info(path)
        self.path, self.rate, self.loop, self.log = path, rate, loop, log
        self.ack_timeout = ack_timeout
        known = {t.name: t for t in self.info.topics}
        if topics:
            unknown = [t for t in topics if t not in known]
            if unknown:
                raise BagError(
                    f"topic {unknown[0]} is not in {path}; it has: {', '.join(sorted(known))}"
                )
            known = {t: known[t] for t in topics}
        duration = (self.info.end - self.info.start) / 1e9
        if start_offset > duration:
            raise BagError(
                f"--start-offset {start_offset} s is past the bag's end ({duration:.3f} s)"
            )
        self.start_ns = self.info.start + int(round(start_offset * 1e9))
        self.topics = known
        classes = {}
        for t in known.values():
            try:
                classes[t.name] = message_class(t.type)
            except (ImportError, AttributeError, ValueError):
                raise BagError(
                    f"topic {t.name} has type {t.type!r}, which is not installed here "
                    f"(leave it out with --topics)"
                ) from None
        self.node = rclpy.create_node(
            "cloth_sim_player", context=context, start_parameter_services=False
        )
        self.publishers = {}
        for t in known.values():
            try:
                offers = parse_qos_profiles(t.offered_qos_profiles)
            except ValueError as e:
                raise BagError(f"topic {t.name}: unreadable offered_qos_profiles ({e})") from None
            self.publishers[t.name] = self.node.create_publisher(
                classes[t.name], t.name, qos_from_offer(offers[0] if offers else None)
            )
        self.published = 0
        self.stop_requested = False

    def run(self) -> float:
        """Publish until the end (or forever with loop, until stopped); returns the wall time
        taken."""
        wall0 = time.perf_counter()
        names = set(self.topics)
        while True:
            t0 = time.perf_counter()
            for topic, msg in iter_messages(self.path, names):
                if self.stop_requested:
                    return time.perf_counter() - wall0
                if msg.log_time < self.start_ns:
                    continue
                due = t0 + (msg.log_time - self.start_ns) / 1e9 / self.rate
                delay = due - time.perf_counter()
                while delay > 0 and not self.stop_requested:
                    time.sleep(min(delay, 0.1))
                    delay = due - time.perf_counter()
                self.publishers[topic.name].publish(bytes(msg.data))
                self.published += 1
            if not self.loop or self.stop_requested:
                self.wait_for_all_acked()
                return time.perf_counter() - wall0

    def wait_for_subscribers(self, poll: float = 0.05) -> bool:
        """Until every topic's publisher has matched at least one subscription (ROS 1's ``rosbag
        play --wait-for-subscribers``: a script or test that subscribes before playing waits for
        discovery however long it takes); ``False`` when stopped first. The subscription matches
        the publisher on its own side a moment apart: ``--delay`` after this covers that."""
        while not self.stop_requested:
            if all(p.get_subscription_count() > 0 for p in self.publishers.values()):
                return True
            time.sleep(poll)
        return False

    def wait_for_all_acked(self) -> bool:
        """Let reliable subscribers acknowledge what was sent before the publishers go away (a DDS
        writer destroyed at exit drops what it has not delivered yet); at most ``ack_timeout``
        seconds."""
        deadline = time.monotonic() + self.ack_timeout
        ok = True
        for pub in self.publishers.values():
            left = max(0.0, deadline - time.monotonic())
            ok &= bool(pub.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9))))
        return ok

    def close(self) -> None:
        self.node.destroy_node()


def main(args) -> int:
    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    player = None
    try:
        player = Player(
            args.bag,
            rate=args.rate,
            loop=args.loop,
            topics=args.topics,
            start_offset=args.start_offset,
            ack_timeout=args.wait_for_all_acked,
            context=context,
        )

        def stop(signum, frame):
            player.stop_requested = True

        signal.signal(signal.SIGINT, stop)
        signal.signal(signal.SIGTERM, stop)
        if args.wait_for_subscribers:
            print(f"waiting for a subscriber on each of {len(player.topics)} topics", flush=True)
            if not player.wait_for_subscribers():
                return 0
        if args.delay > 0:
            # let subscribers discover the publishers first (after --wait-for-subscribers: let
            # each subscriber match its publisher too, which DDS does independently of the
            # publisher matching it: a reliable reader matched late misses what was sent before)
            time.sleep(args.delay)
        print(
            f"playing {args.bag}: {sum(t.count for t in player.topics.values())} messages on "
            f"{len(player.topics)} topics, rate {args.rate:g}",
            flush=True,
        )
        wall = player.run()
        print(f"published {player.published} messages in {wall:.2f} s", flush=True)
    finally:
        if player is not None:
            player.close()
        rclpy.try_shutdown(context=context)
    return 0
