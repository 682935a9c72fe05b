"""The node's running simulation and what its parts share about it, in one object that owns it.

The node builds one :class:`Session` and hands it to each part (the parameter gate, the ticker, the
control, manipulation and publishing, the standard's interfaces). A part reads and changes the
shared state here; what only one part needs (the gate's model cache, the publishers, the
subscriptions) stays in that part.
"""

from __future__ import annotations

import collections

from ..physics.energy_balance import EnergyBalance

#: recovery checkpoints kept: one every :data:`cloth_sim.ros.control.CHECKPOINT_EVERY` s of
#: simulated time, the last CHECKPOINTS
CHECKPOINTS = 20


class Session:
    """The simulation the node runs (``sim``, built from ``scene`` with the values ``cfg``) and its
    run's state: paused or stopped, the last error, the tick's carried time and its history, the
    recovery checkpoints, the poses and twists the manipulated entities are to follow."""

    def __init__(self, scene, cfg: dict, sim, stable_dt: float):
        self.scene, self.cfg, self.sim = scene, cfg, sim
        #: the current method's stable_dt (``inf`` for unconditionally stable methods)
        self.stable_dt = stable_dt
        self.balance = EnergyBalance(sim)  # energy no source put in: WARN on /diagnostics
        self.paused = False
        #: the simulation standard's STATE_STOPPED (paused, and a play starts it again)
        self.stopped = False
        self.error: str | None = None  # why the simulation paused itself (a blow-up)
        self.overruns = 0  # ticks that took longer than their period
        self.dropped = 0.0  # simulated seconds dropped by ticks over their budget
        self.carry = 0.0  # simulated time owed to the next ticks
        self.history = collections.deque()  # (wall, sim time) over the real-time factor's window
        self.tick_costs = collections.deque(maxlen=120)  # (steps, step wall, publish wall)
        self.checkpoints = collections.deque(maxlen=CHECKPOINTS)  # (sim time, saved state)
        self.change_checkpoint = None  # the state before the last accepted live change
        #: (kind, key) -> (position, orientation) to reach over the next tick: kind "collider"
        #: (key: its index) or "gripper" (key: its name)
        self.pose_targets: dict = {}
        #: ``{("collider" | "gripper", name): (linear, angular)}``: kinematic velocities (world
        #: frame, m/s and rad/s) given by the standard's ``set_entity_state``, applied every step
        self.twists: dict = {}
        #: called when the simulation is back at its scene's start (a new scene, a reset)
        self.restart_listeners: list = []
        #: callables that say what is wrong besides the simulation (a string), or None: each
        #: WARNs on /diagnostics (the robot's stale joint states)
        self.problem_sources: list = []

    def replace(self, sim, scene) -> None:
        """A rebuilt simulation (a new scene, or a rebuild value changed): its own energy balance,
        no history, no checkpoints."""
        self.sim, self.scene = sim, scene
        self.balance = EnergyBalance(sim)
        self.forget_run()

    def forget_run(self) -> None:
        """The run so far no longer counts: no time owed, no history, no checkpoints."""
        self.carry = 0.0
        self.history.clear()
        self.checkpoints.clear()
        self.change_checkpoint = None

    def restarted(self) -> None:
        """Tell the listeners the simulation is at its scene's start."""
        for listener in self.restart_listeners:
            listener()
