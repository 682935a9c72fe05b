"""Simulation control: pause, reset and stepping on request (``~/pause``, ``~/reset``, ``~/step``
and the standard's equivalents in :mod:`cloth_sim.ros.sim_interfaces`), and recovery after a
blow-up: the node keeps checkpoints and goes back to one, paused.
"""

from __future__ import annotations

import math
import time

from std_srvs.srv import SetBool, Trigger

from ..simulator import SimulationDiverged
from . import interface

#: the most steps one ~/step request may ask for (the node answers nothing else meanwhile)
MAX_STEP_REQUEST = 100_000
#: recovery checkpoints: one every CHECKPOINT_EVERY s of simulated time (the session keeps the last
#: :data:`cloth_sim.ros.session.CHECKPOINTS`)
CHECKPOINT_EVERY = 0.1


def _srv_types():
    from cloth_sim.srv import Step  # generated from srv/ by rosidl

    return Step


class SimulationControl:
    """Pause, reset, step and recover the node's :class:`~cloth_sim.ros.session.Session`: the
    services ``~/reset``, ``~/pause`` and ``~/step``, and what the standard's services call. Steps
    through ``stepper`` (:class:`~cloth_sim.ros.ticker.Stepper`), publishes through ``publishing``,
    puts the grippers and colliders back through ``manipulation``."""

    def __init__(self, node, session, stepper, publishing, manipulation):
        self.node, self.session = node, session
        self.stepper, self.publishing, self.manipulation = stepper, publishing, manipulation
        interface.service(node, "reset", Trigger, self._on_reset)
        interface.service(node, "pause", SetBool, self._on_pause)
        interface.service(node, "step", _srv_types(), self._on_step)

    def reset_simulation(self, keep_paused: bool = False, spawned: dict | None = None) -> set[str]:
        """The scene as it starts: the cloth's initial shape at rest, time 0, its own grippers
        holding again, its own colliders back where it puts them and at rest (moved, deleted or set
        moving since); colliders spawned since stay only if named in ``spawned`` (``{name:
        (position, orientation)}``: back at that pose, at rest), the others are removed (all of
        them by default). Running afterwards unless ``keep_paused`` (``~/reset`` runs, the
        standard's reset keeps the state). Returns the names of the spawned colliders kept."""
        self.session.sim.reset()  # releases every gripper
        self.manipulation.drop_grippers()
        self.session.scene.apply_grippers(self.session.sim)  # the scene's own grippers hold again
        self.manipulation.adopt_grippers()
        kept = self._restore_colliders(spawned or {})
        self.session.balance.clear()
        self.session.checkpoints.clear()
        self.session.change_checkpoint = None
        self.session.carry = 0.0
        self.session.history.clear()
        self.session.error = None
        if not keep_paused:
            self.session.paused = False
            self.session.stopped = False
        return kept

    def _restore_colliders(self, spawned: dict) -> set[str]:
        """The scene's colliders as the scene makes them, then the ``spawned`` ones at their poses
        (one whose name a scene collider has taken back is dropped); none moving. Returns the
        names of the spawned ones kept."""
        sim = self.session.sim
        own = self.session.scene.make_colliders()
        names = {c.name for c in own}
        kept = [c for c in sim.colliders if c.name in spawned and c.name not in names]
        for i in reversed(range(len(sim.colliders))):
            sim.remove_collider(i)
        for c in own + kept:
            i = sim.add_collider(c)  # it stands where it is added: no sweep from an old pose
            if c.name in spawned:
                sim.set_collider_pose(i, *spawned[c.name], teleport=True)
        self.manipulation.stop_colliders()
        self.manipulation.colliders_changed()
        return {c.name for c in kept}

    def set_paused(self, paused: bool) -> None:
        if not paused and self.session.error:
            self.session.error = (
                None  # the user un-pauses after a blow-up: try again from the good state
            )
        self.session.paused = bool(paused)
        if not paused:
            self.session.stopped = False
        self.session.history.clear()

    def _on_reset(self, request, response):
        self.reset_simulation()  # the scene as it starts: what was spawned is gone
        self.session.restarted()
        response.success = True
        response.message = f"reset {self.session.scene.name} to its initial shape at rest, time 0"
        return response

    def _on_pause(self, request, response):
        self.set_paused(bool(request.data))
        response.success = True
        response.message = "paused" if self.session.paused else "running"
        return response

    def step_paused(self, n: int) -> tuple[bool, str]:
        """Exactly ``n`` steps now, while paused (``~/step``, the standard's ``step_simulation``);
        ``(success, message)``. A blow-up goes back and stays paused, as in a tick."""
        if not self.session.paused:
            return False, "~/step runs only while paused: call ~/pause with data: true first"
        if n > MAX_STEP_REQUEST or n < 0:
            return False, (
                f"steps = {n} is not accepted: expected an integer in "
                f"[0, {MAX_STEP_REQUEST}] (the node answers nothing else while it steps)"
            )
        t0 = time.perf_counter()
        try:
            steps, wall, longest = self.stepper.advance(int(n), t0, math.inf)
        except SimulationDiverged as e:
            self.recover(e)
            return False, self.session.error or str(e)
        self.publishing.publish(t0, steps, wall, longest)
        return True, f"{steps} step{'s' if steps != 1 else ''}"

    def step_within(self, n: int, t0: float, budget: float) -> tuple:
        """Up to ``n`` steps while paused within a tick's ``budget`` (the standard's
        ``simulate_steps``): ``(steps, step wall, longest, None)``, or ``(None, 0, 0, message)``
        after a blow-up (the node went back and paused)."""
        try:
            return (*self.stepper.advance(int(n), t0, budget), None)
        except SimulationDiverged as e:
            self.recover(e)
            return None, 0.0, 0.0, self.session.error or str(e)

    def _on_step(self, request, response):
        response.success, response.message = self.step_paused(int(request.steps))
        response.sim_time = self.session.sim.time
        return response

    def keep_checkpoint(self) -> None:
        if (
            not self.session.checkpoints
            or self.session.sim.time - self.session.checkpoints[-1][0] >= CHECKPOINT_EVERY
        ):
            self.session.checkpoints.append((self.session.sim.time, self.session.sim.save_state()))

    def recover(self, error: SimulationDiverged) -> None:
        """Pause after a blow-up, back at a state from before the run-away began: the one saved
        before the last parameter change when that came within the last second of simulated time
        (a dt or stiffness that does not hold diverges within a few steps, and the steps in
        between are already running away), else the oldest kept checkpoint (up to 2 s back). A
        stable dt and ``~/pause false`` then resume from there."""
        sim = self.session.sim
        candidates = [c for c in (self.session.change_checkpoint,) if c and sim.time - c[0] <= 1.0]
        candidates += list(self.session.checkpoints)[:1]
        if candidates:
            when, saved = candidates[0]
            sim.restore_state(saved)
        self.session.checkpoints.clear()
        self.session.change_checkpoint = None
        self.session.balance.restart()  # back at a state from before the run-away
        self.session.error = str(error)
        self.session.paused = True
        self.session.carry = 0.0
        self.node.get_logger().error(
            f"{error} Went back to t={sim.time:.3f} s and paused: fix the "
            f"parameters, then call ~/pause with data=false, or ~/reset."
        )
        self.publishing.publish_diagnostics()
