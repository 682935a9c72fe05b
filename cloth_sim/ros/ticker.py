"""The node's clock: every tick (``publish_rate`` Hz) advances the simulation by ``1/publish_rate``
s in whole steps of ``dt`` (the remainder carries over) within a budget, then publishes.

:class:`Stepper` takes the steps (reaching the poses received over them, moving the entities set
moving at a twist); :class:`Ticker` owns the timer and the budget of each tick.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..simulator import SimulationDiverged

#: a tick steps for at most this fraction of its period, so parameters and services are answered in
#: time whatever dt is; what does not fit waits for the next ticks, up to MAX_BACKLOG s of
#: simulated time, and beyond that is dropped (the real-time factor falls below 1, /diagnostics
#: warns). A tick that starts late (the executor was busy) steps that much less, so that it still
#: ends by its own deadline: an overloaded node whose ticks each ran their full budget from a late
#: start drifted past the timer's next period, which rcl then skips (gaps of 3–4 periods in the
#: fuzz).
TICK_BUDGET = 0.8
MAX_BACKLOG = 0.25
#: with real_time_factor 0 a tick steps until its budget is spent, at most this many steps
MAX_STEPS_PER_TICK = 1_000_000


class Stepper:
    """Steps the session's simulation; the poses and twists of ``manipulation`` are followed."""

    def __init__(self, session, manipulation, robot_state):
        self.session, self.manipulation, self.robot_state = session, manipulation, robot_state

    def advance(self, n: int, t0: float, budget: float) -> tuple[int, float, float]:
        """Up to ``n`` steps, stopping once ``budget`` s have passed since ``t0``; poses received
        for colliders and grippers are reached over them. Returns ``(steps, step wall,
        longest)``."""
        session, manip = self.session, self.manipulation
        sim = session.sim
        moves = manip.pose_moves() if session.pose_targets and n else None
        sweep = sim.sweeps_colliders  # (else a collider's pose is placed step by step)
        if moves and not sweep and any(kind == "collider" for kind, _ in moves):
            manip.node.get_logger().warning(
                f"on the {sim.device} device under {sim.integrator} a collider moved by its pose "
                "topic is placed at rest step by step (its swept motion is not there yet: "
                "friction does not drag what it carries)",
                once=True,
            )
        joints = self.robot_state.joint_move() if n else None  # (robot, from, to)
        links = self.robot_state.tf_move() if n else None  # (robot, {link: transform})
        if links:  # the links' poses from TF: swept there over the first step
            sim.set_link_transforms(*links)
        # joints are reached over the steps this tick is expected to take (a late tick takes
        # fewer than n: a message is then still reached within it)
        jspan = max(1, min(n, int(budget / max(self.step_cost(), 1e-6)))) if joints else 1
        steps, step_wall, step_max = 0, 0.0, 0.0
        span = n if n < MAX_STEPS_PER_TICK else max(1, int(budget / max(self.step_cost(), 1e-6)))
        for k in range(n):
            if moves:  # a pose received since the last tick: reached over this tick's steps
                f = min(1.0, (k + 1) / span)
                for (kind, key), (p0, q0, p1, q1) in moves.items():
                    q = (1 - f) * q0 + f * q1
                    q /= np.linalg.norm(q)
                    if kind == "collider":
                        sim.set_collider_pose(key, (1 - f) * p0 + f * p1, q, teleport=not sweep)
                    else:  # pose_moves kept only grippers that hold; none is released mid-tick
                        sim.set_gripper_pose(key, (1 - f) * p0 + f * p1, q)
                if f >= 1.0:
                    moves = None
            if joints:  # joint states received since the last tick: reached over its steps
                f = min(1.0, (k + 1) / jspan)
                name, q0, q1 = joints
                sim.set_joint_positions(name, {j: (1 - f) * q0[j] + f * q1[j] for j in q1})
                if f >= 1.0:
                    joints = None
            if session.twists:  # colliders and grippers moving at a set velocity
                manip.apply_twists(sim.dt)
            s0 = time.perf_counter()
            sim.step()
            el = time.perf_counter() - s0
            step_wall += el
            step_max = max(step_max, el)
            steps += 1
            # stop before a step that would end past the budget, predicting its cost by the last
            # one's: a tick then overruns only when a step takes longer than the one before it
            if s0 + 2.0 * el - t0 > budget:
                break
        if moves:  # the tick ended before the poses were reached: the rest next tick
            for (kind, key), (_, _, p1, q1) in moves.items():
                session.pose_targets.setdefault((kind, key), (p1, q1))
        if joints:  # the tick ended early (overloaded): the rest in the next step, so the
            # links stand at the joint state the tick took (within one tick, whatever its steps)
            sim.set_joint_positions(joints[0], joints[2])
        return steps, step_wall, step_max

    def step_cost(self) -> float:
        """The median wall time of a step over the last ticks (s)."""
        costs = [w / s for s, w, _ in self.session.tick_costs if s]
        return float(np.median(costs)) if costs else 1e-4


class Ticker:
    """The node's timer and each tick's budget: steps (``stepper``), keeps the recovery checkpoints
    and recovers from a blow-up (``control``), lets a running ``simulate_steps`` goal step while
    paused (``interfaces``), publishes (``publishing``)."""

    def __init__(self, node, session, stepper, control, publishing, interfaces):
        self.node, self.session, self.stepper = node, session, stepper
        self.control, self.publishing, self.interfaces = control, publishing, interfaces
        self.next_tick = None  # perf_counter time the next tick is due (the budget's deadline)
        self.last_tick = None  # perf_counter time the last tick started
        self._resync = False  # the next tick's deadline is not on its timer's grid (a new rate)
        self.timer = node.create_timer(1.0 / session.cfg["publish_rate"], self.tick)

    def set_rate(self, rate: float) -> None:
        """A new ``publish_rate``: a new timer, whose first tick is due a new period after the last
        tick (it steps that much less, its budget's deadline), so the ``~/stats`` interval across
        the change stays under 1.8 new periods (it reached 2)."""
        self.timer.cancel()
        self.node.destroy_timer(self.timer)
        self.timer = self.node.create_timer(1.0 / rate, self.tick)
        self.next_tick = None if self.last_tick is None else self.last_tick + 1.0 / rate
        self._resync = True

    def tick(self) -> None:
        t0 = time.perf_counter()
        session = self.session
        period = 1.0 / session.cfg["publish_rate"]
        # how late this tick starts against the period grid of the previous ones
        expected = self.next_tick
        late = t0 - expected if expected is not None and t0 > expected else 0.0
        self.next_tick = (
            expected + period
            if expected is not None and late < period and not self._resync
            else t0 + period
        )
        self.last_tick, self._resync = t0, False
        sim = session.sim
        steps, step_max, step_wall = 0, 0.0, 0.0
        energy = None  # the state's energies, for the balance and ~/stats both (once a tick)
        if not session.paused:
            target = session.cfg["real_time_factor"]
            budget = max(0.25 * period, TICK_BUDGET * period - late)
            if target > 0:
                session.carry += period * target
                n = int(math.floor(session.carry / sim.dt + 1e-9))
                session.carry -= n * sim.dt
            else:  # as fast as the CPU allows: steps until the tick's budget is spent
                n, session.carry = MAX_STEPS_PER_TICK, 0.0
            try:
                steps, step_wall, step_max = self.stepper.advance(n, t0, budget)
                if target > 0:
                    session.carry += (n - steps) * sim.dt  # what did not fit waits for next ticks
                    backlog = MAX_BACKLOG * max(target, 1.0)
                    if session.carry > backlog:
                        session.dropped += session.carry - backlog
                        session.carry = backlog
                self.control.keep_checkpoint()
                energy = sim.energy()
                session.balance.sample(energy)
            except SimulationDiverged as e:
                self.control.recover(e)
        elif self.interfaces.busy:  # a simulate_steps goal steps the paused simulation
            budget = max(0.25 * period, TICK_BUDGET * period - late)
            steps, step_wall, step_max = self.interfaces.tick(t0, budget)
        self.publishing.publish(t0, steps, step_wall, step_max, energy)
        if time.perf_counter() - t0 > period:
            session.overruns += 1
