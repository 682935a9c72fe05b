"""ClothFold as one Gymnasium ``VectorEnv`` over one :class:`~cloth_sim.BatchSimulator`:
``num_envs`` cloths stepped together, on the CPU or, with ``device="cuda"``, in the same GPU
launches (:mod:`cloth_sim.cuda`).

::

    envs = ClothFoldVectorEnv(num_envs=1024, device="cuda")
    envs = gymnasium.make_vec("cloth_sim/ClothFold-v0", num_envs=1024, device="cuda")

Each world is :class:`~cloth_sim.envs.tasks.ClothFoldEnv`'s: the same cloth, initial states
(its cache), pickers, physics (symplectic Euler with Provot's strain limit and a floor:
:meth:`~cloth_sim.envs.cloth_env.ClothEnv.simulator_options`), metric and spaces; the keywords are
its keywords. What differs, and why:

* **Observations** are ``"key_point"`` only, **actions** ``"picker"`` only: a point cloud or a
  depth image is a camera render a world on the host, and a pick-and-place runs a number of
  frames of its own in each world; ``gymnasium.make_vec(..., vectorization_mode="async")`` runs
  those.
* **Pickers** move the particles they hold along the same straight lines, a frame at a time
  (:meth:`~cloth_sim.BatchSimulator.drag`): on the device a held particle moves at the frame's
  constant velocity, one launch for the frame's steps.
* **Autoreset** is Gymnasium's next-step mode (as ``SyncVectorEnv``): a world whose episode ended
  is reset by the next :meth:`step`, which ignores its action and returns its first observation,
  reward 0. Every world steps in every call (the batch steps together); a world being reset is
  put back to its initial state after the call's frames.
* Rewards and infos are numpy arrays on the host (on the device the metric is computed there and
  only its means come back). Observations are too, or with ``observations="device"`` (cuda) a
  ``(num_envs, 18)`` float32 device array gathered by a kernel (``__cuda_array_interface__``:
  ``torch.as_tensor`` and ``cupy.asarray`` read it without a copy), the same numbers;
  :attr:`positions` is every particle on the device. An env step copies no cloth to the host.

With ``device="cpu"`` the cloth is the single env's to rounding (the tests hold it to
``SyncVectorEnv``'s); with ``device="cuda"`` the strain limit's passes visit the springs a colour
at a time, so it differs from the CPU's where the limit acts (docs/gpu.md).
"""

from __future__ import annotations

import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .. import backends
from ..batch import BatchSimulator
from . import metrics
from .cloth_env import check_integer
from .pickers import centred_bounds, on_circle
from .tasks import ClothFoldEnv


class ClothFoldVectorEnv(VectorEnv):
    """``num_envs`` ClothFold worlds on ``device`` (``"cpu"`` or ``"cuda"``); ``precision`` and
    ``launch`` are the cuda device's (:class:`~cloth_sim.cuda.worlds.CudaWorlds`),
    ``observations`` ``"host"`` (numpy) or, on cuda, ``"device"``; the rest
    :class:`~cloth_sim.envs.tasks.ClothFoldEnv`'s keywords. Bad input raises ``ValueError``
    naming it."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(
        self,
        num_envs: int = 1,
        device: str = "cpu",
        precision=None,
        launch=None,
        observations: str = "host",
        **env_kwargs,
    ):
        self.num_envs = check_integer("num_envs", num_envs, 1)
        try:  # (before the single env is made: its initial states take seconds)
            backends.check_device(device)
        except ValueError as e:
            raise ValueError(f"device = {device!r} is not accepted: {e}") from None
        if observations not in ("host", "device") or (
            observations == "device" and device != "cuda"
        ):
            raise ValueError(
                f"observations = {observations!r} is not accepted on device={device!r}: "
                "expected 'host'" + (" or 'device'" if device == "cuda" else "")
            )
        self.observations = observations
        for name, value, allowed in (
            ("observation_mode", env_kwargs.get("observation_mode", "key_point"), "key_point"),
            ("action_mode", env_kwargs.get("action_mode", "picker"), "picker"),
        ):
            if value != allowed:
                raise ValueError(
                    f"{name} = {value!r} is not accepted by the vector env: expected {allowed!r} "
                    "(gymnasium.make_vec(..., vectorization_mode='async') runs the others)"
                )
        if env_kwargs.get("render_mode") is not None:
            raise ValueError(
                f"render_mode = {env_kwargs['render_mode']!r} is not accepted by the vector env: "
                "expected None"
            )
        #: the single env every world copies (its cloth, states, pickers, spaces), on the CPU
        self.env = env = ClothFoldEnv(**env_kwargs)
        options = env.simulator_options()
        device_options = {
            k: v for k, v in (("precision", precision), ("launch", launch)) if v is not None
        }
        if device == "cuda":
            if options.pop("self_collision"):
                raise ValueError(
                    "self_collision = True is not accepted on the cuda device: self-contact is "
                    "not there yet (device='cpu' has it)"
                )
            options.update(device_options)
        elif device_options:
            raise ValueError(
                f"{', '.join(device_options)}: the cuda device's options; device={device!r} "
                "takes none"
            )
        self.device = device
        #: every world's cloth
        self.sim = BatchSimulator(env.model, worlds=self.num_envs, device=device, **options)
        self.substeps = env.substeps
        self.single_observation_space = env.observation_space
        self.single_action_space = env.action_space
        self.observation_space = batch_space(env.observation_space, self.num_envs)
        self.action_space = batch_space(env.action_space, self.num_envs)
        w, p = self.num_envs, env.num_picker
        pk = env.pickers
        self._span = (np.array(pk.low), np.array(pk.high))
        #: each world's pickers' centres, their bounds, and what each holds (a particle, or −1)
        #: at which offset from the picker
        self.pickers = np.zeros((w, p, 3))
        self.low = np.tile(self._span[0], (w, 1))
        self.high = np.tile(self._span[1], (w, 1))
        self.held = np.full((w, p), -1, np.int64)
        self.offset = np.zeros((w, p, 3))
        self.variation = np.zeros(w, np.int64)
        self.steps = np.zeros(w, np.int64)
        self.group_a, self.group_b = metrics.fold_groups(env.rows, env.cols)
        self.performance_start = np.zeros(w)
        self._ended = np.zeros(w, bool)
        self._rngs = [None] * w

    # ------------------------------------------------------------------ Gymnasium
    def reset(self, *, seed=None, options=None):
        """Every world to an initial state: ``seed`` an integer (world ``i`` seeded ``seed + i``,
        as ``SyncVectorEnv`` seeds its envs), a list (one a world) or None; ``options``
        ``{"variation": int or one a world}``."""
        super().reset(seed=seed if isinstance(seed, (int, np.integer)) else None)
        options = dict(options or {})
        unknown = set(options) - {"variation"}
        if unknown:
            raise ValueError(f"reset options: unknown {sorted(unknown)}; accepted: 'variation'")
        w = self.num_envs
        if seed is None or isinstance(seed, (int, np.integer)):
            seeds = [None if seed is None else int(seed) + i for i in range(w)]
        else:
            seeds = list(seed)
            if len(seeds) != w:
                raise ValueError(f"seed: expected an integer or {w} of them, got {len(seeds)}")
        for i, s in enumerate(seeds):
            if s is not None or self._rngs[i] is None:
                self._rngs[i], _ = seeding.np_random(s)
        variations = None
        if "variation" in options:
            v = np.broadcast_to(np.asarray(options["variation"]), (w,))
            variations = [
                check_integer(f"options['variation'][{i}]", int(x), 0, self.env.num_variations - 1)
                for i, x in enumerate(v)
            ]
        self._reset_worlds(np.arange(w), variations)
        self._ended[:] = False
        return self._observe(), self._infos()

    def step(self, actions):
        a = self._check(actions)
        renew = np.flatnonzero(self._ended)
        act = ~self._ended
        pick = (a[:, :, 3] > 0.5) & act[:, None]
        delta = np.clip(a[:, :, :3], -self.env.pickers.max_move, self.env.pickers.max_move)
        delta[~act] = 0.0
        for _ in range(self.env.action_repeat):
            self._frame(delta, pick)
        if len(renew):
            self._reset_worlds(renew, None)
        self.steps[act] += 1
        obs, infos = self._observe(), self._infos()
        reward = np.where(act, infos["performance"], 0.0)
        terminated = np.zeros(self.num_envs, bool)
        truncated = act & (self.steps >= self.env.horizon)
        self._ended = terminated | truncated
        return obs, reward, terminated, truncated, infos

    def close_extras(self, **kwargs):
        pass

    # ------------------------------------------------------------------ the worlds
    @property
    def positions(self):
        """``(num_envs, n, 3)``: every world's particles (on the device a device array)."""
        return self.sim.positions

    def _reset_worlds(self, ids, variations) -> None:
        """Worlds ``ids`` to their variation's initial state (``variations``, or drawn from each
        world's generator as the single env draws it), nothing held, the pickers placed and the
        metric's baselines noted (ClothFold's ``_start``)."""
        env = self.env
        held = self.held[ids]
        rows = np.nonzero(held >= 0)
        if len(rows[0]):
            self.sim.release_pairs(ids[rows[0]], held[rows])
        self.held[ids] = -1
        x = np.empty((len(ids), env.model.n_particles, 3))
        v = np.empty_like(x)
        for r, w in enumerate(ids):
            if variations is None:
                var = int(self._rngs[w].integers(env.num_variations))
            else:
                var = variations[w]
            state = env.states.get(var)
            self.variation[w] = var
            x[r], v[r] = state["positions"], state["velocities"]
        self.sim.write(ids, x, v)
        self.steps[ids] = 0
        mid = x[:, env.corners[:2]].mean(axis=1)
        self._place_pickers(ids, np.column_stack([mid[:, 0], mid[:, 1], np.full(len(ids), 0.1)]))
        self.performance_start[ids] = self._fold()[0][ids]

    def _place_pickers(self, ids, centers) -> None:
        """:meth:`Pickers.reset <cloth_sim.envs.pickers.Pickers.reset>` for worlds ``ids``: the
        bounds centred on ``centers`` horizontally, the pickers on a circle about them."""
        pk = self.env.pickers
        self.low[ids], self.high[ids] = centred_bounds(centers, *self._span)
        self.pickers[ids] = on_circle(centers, pk.count, pk.radius, self.low[ids], self.high[ids])

    def _frame(self, delta, pick) -> None:
        """One frame of every world (:meth:`Pickers.frame <cloth_sim.envs.pickers.Pickers.frame>`
        for all at once): a picker whose flag is off lets go, one whose flag is on and holds
        nothing takes the nearest free particle within reach, then the pickers move by
        ``delta`` (clipped to their bounds) over the frame's steps, dragging what they hold."""
        let_go = (self.held >= 0) & ~pick
        if let_go.any():
            w, p = np.nonzero(let_go)
            self.sim.release_pairs(w, self.held[w, p])
            self.held[w, p] = -1
        want = pick & (self.held < 0)
        if want.any():
            self._grasp(want)
        start = self.pickers
        end = np.clip(start + delta, self.low[:, None], self.high[:, None])
        w, p = np.nonzero(self.held >= 0)
        self.sim.drag(
            w,
            self.held[w, p],
            end[w, p] + self.offset[w, p],
            self.substeps,
            starts=start[w, p] + self.offset[w, p],
        )
        self.pickers = end

    def _grasp(self, want) -> None:
        """Pickers ``want`` (``(worlds, pickers)``) take the nearest particle within reach that
        is free: not pinned, not held by another picker (a world's pickers in turn, every world
        at once: :meth:`~cloth_sim.BatchSimulator.nearest_free`, on the device a launch that
        returns the rows alone)."""
        reach = self.env.pickers.reach
        for p in range(self.held.shape[1]):
            w = np.flatnonzero(want[:, p])
            if not len(w):
                continue
            j, at = self.sim.nearest_free(w, self.pickers[w, p])
            offset = at - self.pickers[w, p]
            ok = (j >= 0) & (np.linalg.norm(offset, axis=1) <= reach)
            if ok.any():
                self.sim.hold_pairs(w[ok], j[ok])
                self.held[w[ok], p] = j[ok]
                self.offset[w[ok], p] = offset[ok]

    def _check(self, actions) -> np.ndarray:
        w, p = self.num_envs, self.env.num_picker
        try:
            a = np.asarray(actions, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(
                f"actions: expected ({w}, {4 * p}) numbers ([dx, dy, dz, pick] for each of {p} "
                f"pickers, a row a world), got {actions!r}"
            ) from None
        if a.shape != (w, 4 * p):
            raise ValueError(
                f"actions: expected shape ({w}, {4 * p}) ([dx, dy, dz, pick] for each of {p} "
                f"pickers, a row a world), got shape {a.shape}"
            )
        bad = np.argwhere(~np.isfinite(a))
        if len(bad):
            i, j = bad[0]
            raise ValueError(f"actions[{i}, {j}] = {a[i, j]} is not finite")
        return a.reshape(w, p, 4)

    # ------------------------------------------------------------------ what is seen
    def _fold(self):
        """ClothFold's metric (:func:`~cloth_sim.envs.metrics.fold_distance`) of every world:
        ``(performance, group distance, fixation distance)``, each ``(num_envs,)``, the drift
        measured from where the world was reset (:meth:`BatchSimulator.mean_distance
        <cloth_sim.BatchSimulator.mean_distance>`: on the device, only the means come back)."""
        group = self.sim.mean_distance(self.group_a, self.group_b)
        fixation = self.sim.mean_distance(self.group_b, self.group_b, reference=True)
        return -group - 1.2 * fixation, group, fixation

    def _observe(self):
        """``"key_point"``: each world's four corners, then its pickers, float32 (gathered on the
        device on cuda, and left there where ``observations="device"``)."""
        obs = self.sim.gather(self.env.corners, self.pickers)
        if self.device == "cuda" and self.observations == "host":
            return obs.copy_to_host()
        return obs

    def _infos(self) -> dict:
        performance, group, fixation = self._fold()
        base = self.performance_start
        span = 0.0 - base
        normalized = np.divide(
            performance - base, span, out=np.zeros_like(base), where=span != 0.0
        )
        info = dict(
            performance=performance,
            normalized_performance=normalized,
            variation=self.variation.copy(),
            picked=self.held >= 0,
            neg_group_dist=-group,
            neg_fixation_dist=-fixation,
        )
        every = np.ones(self.num_envs, bool)
        return {**info, **{f"_{k}": every for k in info}}
