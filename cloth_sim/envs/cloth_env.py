"""The common part of the cloth tasks: a Gymnasium environment over a cloth_sim :class:`Simulator`.

What SoftGym's ``ClothEnv``/``FlexEnv`` do (Lin et al. 2020), on cloth_sim's physics and grippers:

* **Time.** A *frame* is 1/60 s, FleX's step in SoftGym; an env step is ``action_repeat`` frames
  with the same action (SoftGym's defaults: 8 for ClothFlatten and ClothFold, 16 for ClothDrop, 1
  for pick-and-place). Each frame is ``SUBSTEPS`` steps of symplectic Euler with Provot's strain
  limit (10 %), a floor with friction, and (optionally) self-collision.
* **Actions.** ``action_mode="picker"``: ``[dx, dy, dz, pick]`` per picker, each move at most
  0.01 m per frame, ``pick > 0.5`` holds the nearest particle within reach (:mod:`.pickers`).
  ``"pickerpickplace"``: ``[x, y, z, pick]`` per picker, a target the pickers go to at 0.01 m per
  frame (at most 300 frames) holding or not.
* **Observations.** ``"key_point"``: the cloth's four corners and the pickers, world frame
  (SoftGym's reduced state). ``"point_cloud"``: what the depth camera sees of the cloth, in the
  camera's optical frame, ``max_points`` points (a seeded random subset when more are visible,
  zeros after the last when fewer; ``info["points"]`` is the count), then the pickers in the same
  frame. ``"depth"``: the depth image (metres, 0 where nothing is seen).
* **Initial states** come from :mod:`.initial_states`: variation ``i`` of ``num_variations`` is
  generated from the seed ``[task, i]`` the first time it is needed and cached on disk, so
  ``reset(seed=s)`` is the same episode wherever and whenever it runs.
* ``info["normalized_performance"]`` is the task's metric at every step, as SoftGym names it, with
  ``info["performance"]`` (also the reward, as in SoftGym).

Subclasses (:mod:`.tasks`) give the cloth, how a variation is generated, where the pickers start
and the metric.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from ..contact import colliders
from ..model import ClothModel
from ..sensors.camera import camera_from_settings
from ..simulator import Simulator
from . import initial_states
from .pickers import Pickers
from .render import render_rgb

FRAME = 1.0 / 60.0
SUBSTEPS = 8
OBSERVATION_MODES = ("key_point", "point_cloud", "depth")
ACTION_MODES = ("picker", "pickerpickplace")
RENDER_MODES = ("rgb_array", "depth_array")
#: SoftGym's particle radius (m): part of a picker's reach
PARTICLE_RADIUS = 0.00625
PICK_PLACE_MOVE = 0.01
PICK_PLACE_FRAMES = 300


def _choice(name, value, allowed):
    if value not in allowed:
        raise ValueError(
            f"{name} = {value!r} is not accepted: expected one of {', '.join(map(repr, allowed))}"
        )
    return value


def check_integer(name, value, lo, hi=None):
    """``value`` as an int in ``[lo, hi]`` (``hi`` None: no upper bound), else ``ValueError``
    naming ``name`` and the range."""
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, np.integer))
        or value < lo
        or (hi is not None and value > hi)
    ):
        rng = f"[{lo}, {hi}]" if hi is not None else f">= {lo}"
        raise ValueError(f"{name} = {value!r} is not accepted: expected an integer {rng}")
    return int(value)


def _positive(name, value):
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float, np.floating, np.integer))
        or not math.isfinite(value)
        or value <= 0
    ):
        raise ValueError(f"{name} = {value!r} is not accepted: expected a finite number > 0")
    return float(value)


class ClothEnv(gym.Env):
    """See the module docstring. Keyword arguments (all checked, ``ValueError`` naming the one that
    is wrong): ``observation_mode``, ``action_mode``, ``num_picker``, ``render_mode``,
    ``cloth_size`` ``(rows, cols)``, ``spacing`` (m), ``horizon`` (env steps), ``action_repeat``
    (frames per env step), ``num_variations``, ``image_size`` (pixels, square), ``max_points``,
    ``self_collision``, ``cache_dir`` (``None``: the user cache; ``False``: none)."""

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 15}
    #: the task's name (the cache's key and the seed's first word)
    task = "Cloth"
    #: what the task asks, in words (a dataset's task string)
    instruction = ""
    defaults = dict(horizon=100, action_repeat=8)
    #: bounds of the pickers' centres, (x, y, z) low and high before centring, z up: SoftGym's
    #: ``(-0.4, 0, -0.4)``–``(1.0, 0.5, 0.4)`` (y up) less the picker's radius, but down to the
    #: height of a particle on the floor (see :mod:`.pickers`)
    picker_bounds = ((-0.38, -0.38, 0.004), (0.98, 0.38, 0.48))
    picker_radius = 0.02
    camera = dict(position=(0.0, -0.82, 0.82), look_at=(0.0, 0.0, 0.0), fov=45.0)

    def __init__(
        self,
        observation_mode: str = "key_point",
        action_mode: str = "picker",
        num_picker: int = 2,
        render_mode: str | None = None,
        cloth_size=(24, 24),
        spacing: float = 0.0175,
        horizon: int | None = None,
        action_repeat: int | None = None,
        num_variations: int = 1000,
        image_size: int = 128,
        max_points: int = 1024,
        self_collision: bool = False,
        cache_dir=None,
    ):
        self.observation_mode = _choice("observation_mode", observation_mode, OBSERVATION_MODES)
        self.action_mode = _choice("action_mode", action_mode, ACTION_MODES)
        self.render_mode = (
            None if render_mode is None else _choice("render_mode", render_mode, RENDER_MODES)
        )
        self.num_picker = check_integer("num_picker", num_picker, 1, 8)
        try:
            rows, cols = cloth_size
        except (TypeError, ValueError):
            raise ValueError(
                f"cloth_size = {cloth_size!r} is not accepted: expected (rows, cols)"
            ) from None
        self.rows = check_integer("cloth_size[0] (rows)", rows, 4, 256)
        self.cols = check_integer("cloth_size[1] (cols)", cols, 4, 256)
        self.spacing = _positive("spacing", spacing)
        default_repeat = 1 if action_mode == "pickerpickplace" else self.defaults["action_repeat"]
        self.horizon = check_integer(
            "horizon", self.defaults["horizon"] if horizon is None else horizon, 1
        )
        self.action_repeat = check_integer(
            "action_repeat", default_repeat if action_repeat is None else action_repeat, 1, 1000
        )
        if self.action_mode == "pickerpickplace" and self.action_repeat != 1:
            raise ValueError(
                f"action_repeat = {action_repeat!r} is not accepted with action_mode "
                f"'pickerpickplace': expected 1 (a pick-and-place is one env step)"
            )
        self.num_variations = check_integer("num_variations", num_variations, 1)
        self.image_size = check_integer("image_size", image_size, 8, 2048)
        self.max_points = check_integer("max_points", max_points, 1)
        if not isinstance(self_collision, (bool, np.bool_)):
            raise ValueError(
                f"self_collision = {self_collision!r} is not accepted: expected True or False"
            )
        self.self_collision = bool(self_collision)
        self._check_task()

        self.model = self._model()
        self.sim = self._simulator()
        if not self.sim.step_is_stable():
            raise ValueError(
                f"the cloth's springs need a step below {self.sim.stable_dt():.3g} s, "
                f"above the env's {self.sim.dt:.3g} s"
            )
        self.cam = camera_from_settings(
            dict(
                width=self.image_size,
                height=self.image_size,
                near=0.05,
                far=10.0,
                noise="none",
                **self.camera,
            )
        )
        self.pickers = Pickers(
            self.num_picker,
            self.picker_radius,
            self.picker_radius + 0.005 + PARTICLE_RADIUS,
            0.01,
            *self.picker_bounds,
        )
        self.corners = self._key_points()
        self.states = initial_states.Cache(self.task, self._cache_key(), self._generate, cache_dir)

        p = self.num_picker
        if self.action_mode == "picker":
            self.action_space = spaces.Box(
                np.tile(np.float32([-0.01, -0.01, -0.01, 0.0]), p),
                np.tile(np.float32([0.01, 0.01, 0.01, 1.0]), p),
                dtype=np.float32,
            )
        else:
            lo, hi = self.pick_place_bounds
            self.action_space = spaces.Box(
                np.tile(np.float32([*lo, 0.0]), p),
                np.tile(np.float32([*hi, 1.0]), p),
                dtype=np.float32,
            )
        if self.observation_mode == "key_point":
            n = 3 * (len(self.corners) + p)
            self.observation_space = spaces.Box(-np.inf, np.inf, (n,), np.float32)
        elif self.observation_mode == "point_cloud":
            n = 3 * (self.max_points + p)
            self.observation_space = spaces.Box(-np.inf, np.inf, (n,), np.float32)
        else:
            self.observation_space = spaces.Box(
                0.0, np.float32(self.cam.far), (self.image_size, self.image_size), np.float32
            )
        self.variation = None
        self.steps = 0

    pick_place_bounds = ((-0.5, -0.5, 0.0), (0.5, 0.5, 0.3))
    thickness = 0.004

    # ------------------------------------------------------------------ the task's part
    def _check_task(self) -> None:
        """Refuse settings the task cannot take."""

    def _generate(self, rng: np.random.Generator) -> dict:
        """Variation from ``rng``: a dict with at least ``positions`` and ``velocities``."""
        raise NotImplementedError

    def _start(self) -> None:
        """After the state is set: place the pickers, note the metric's baselines."""
        raise NotImplementedError

    def _performance(self) -> tuple[float, dict]:
        """``(performance, extra info)`` now."""
        raise NotImplementedError

    def _normalized(self, performance: float) -> float:
        raise NotImplementedError

    # ------------------------------------------------------------------ the cloth
    @property
    def particle_mass(self) -> float:
        """0.2 kg/m² (a light cotton) times the area a particle stands for."""
        return 0.2 * self.spacing**2

    def _model(self) -> ClothModel:
        m = self.particle_mass
        # stiffness and damping per unit mass as the `fold` scene has them (k/m = 1e5 s⁻² there;
        # a quarter here, which puts the stable step at twice the env's), the strain limit
        # holding the stretch
        k = 2.5e4 * m
        return ClothModel.grid(
            self.rows,
            self.cols,
            self.spacing,
            m,
            stiffness={"structural": k, "shear": k, "bend": 0.01 * k},
            damping={"structural": 2 * m, "shear": 2 * m, "bend": 0.5 * m},
        )

    #: simulation steps a frame (each ``FRAME / substeps``)
    substeps = SUBSTEPS

    def simulator_options(self) -> dict:
        """The simulator's arguments: symplectic Euler, ``substeps`` steps a frame, Provot's
        strain limit, a floor (:mod:`.vector` steps many worlds with the same)."""
        return dict(
            integrator="symplectic_euler",
            dt=FRAME / self.substeps,
            strain_limit=0.1,
            colliders=[colliders.Plane(normal=(0, 0, 1), offset=0.0, friction=0.5, name="floor")],
            thickness=self.thickness,
            self_collision=self.self_collision,
        )

    def _simulator(self) -> Simulator:
        return Simulator(self.model, **self.simulator_options())

    def _key_points(self) -> np.ndarray:
        """The particles ``"key_point"`` observes: the grid's four corners."""
        return np.array([0, self.cols * (self.rows - 1), self.cols - 1, self.rows * self.cols - 1])

    def _cache_key(self) -> dict:
        return dict(
            task=self.task,
            rows=self.rows,
            cols=self.cols,
            spacing=self.spacing,
            num_picker=self.num_picker,
            self_collision=self.self_collision,
            frame=FRAME,
            substeps=self.substeps,
            thickness=self.thickness,
        )

    def flat_positions(self) -> np.ndarray:
        """The grid lying flat on the floor, centred on the origin."""
        x = self.model.positions.copy()
        x[:, :2] -= x[:, :2].mean(axis=0)
        x[:, 2] = self.thickness
        return x

    def lay_flat(self) -> np.ndarray:
        """Put the cloth flat on the floor at rest (:meth:`flat_positions`); returns the
        positions."""
        x = self.flat_positions()
        self._set_state(x, np.zeros_like(x))
        return x

    def frames(self, n: int, until=None) -> int:
        """Step ``n`` frames with nothing held moving, or fewer: until ``until()`` holds."""
        for i in range(n):
            self.sim.step(self.substeps)
            if until is not None and until():
                return i + 1
        return n

    def still(self, threshold: float):
        return lambda: float(np.abs(self.sim.velocities).max()) < threshold

    def _set_state(self, x, v) -> None:
        for name in list(self.sim.grippers):
            self.sim.release(name)
        self.pickers.held = [None] * self.num_picker
        self.sim.positions = x
        self.sim.velocities = v
        self.sim.set_time(0.0)

    # ------------------------------------------------------------------ Gymnasium
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = set(options) - {"variation"}
        if unknown:
            raise ValueError(f"reset options: unknown {sorted(unknown)}; accepted: 'variation'")
        if "variation" in options:
            self.variation = check_integer(
                "options['variation']", options["variation"], 0, self.num_variations - 1
            )
        else:
            self.variation = int(self.np_random.integers(self.num_variations))
        state = self.states.get(self.variation)
        self._set_state(state["positions"], state["velocities"])
        self.steps = 0
        self._start()
        return self._observe()

    def step(self, action):
        a = self._check_action(action)
        if self.action_mode == "picker":
            for _ in range(self.action_repeat):
                self.pickers.frame(self.sim, a[:, :3], a[:, 3] > 0.5, self.substeps)
        else:
            self._pick_place(a)
        self.steps += 1
        obs, info = self._observe()
        return obs, info["performance"], False, self.steps >= self.horizon, info

    def _pick_place(self, a) -> None:
        """SoftGym's ``PickerPickPlace.step``: straight to the (clipped) targets at 0.01 m per
        frame for the farthest picker, the pick flags held throughout, at most 300 frames."""
        end = np.array([self.pickers.clip(p) for p in a[:, :3]])
        dist = np.linalg.norm(end - self.pickers.positions, axis=1)
        n = int(np.ceil(dist.max() / PICK_PLACE_MOVE))
        pick = a[:, 3] > 0.5
        for i in range(min(n, PICK_PLACE_FRAMES)):
            delta = (end - self.pickers.positions) / (n - i)
            self.pickers.frame(self.sim, delta, pick, self.substeps)
        if n == 0:  # no move: the flags still act, over one frame
            self.pickers.frame(self.sim, np.zeros((self.num_picker, 3)), pick, self.substeps)

    def _check_action(self, action) -> np.ndarray:
        shape = self.action_space.shape
        what = "[dx, dy, dz, pick]" if self.action_mode == "picker" else "[x, y, z, pick]"
        try:
            a = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(
                f"action: expected {shape[0]} numbers ({what} for each of "
                f"{self.num_picker} pickers), got {action!r}"
            ) from None
        if a.shape != shape:
            raise ValueError(
                f"action: expected shape {shape} ({what} for each of {self.num_picker} "
                f"pickers), got shape {a.shape}"
            )
        bad = np.flatnonzero(~np.isfinite(a))
        if len(bad):
            i = int(bad[0])
            raise ValueError(
                f"action[{i}] = {float(a[i])} (picker {i // 4}, {what[1:-1].split(', ')[i % 4]}) "
                f"is not finite"
            )
        return a.reshape(self.num_picker, 4)

    def _observe(self):
        performance, extra = self._performance()
        info = dict(
            performance=performance,
            normalized_performance=self._normalized(performance),
            variation=self.variation,
            picked=[h is not None for h in self.pickers.held],
            **extra,
        )
        mode = self.observation_mode
        if mode == "key_point":
            obs = self.key_point_state()
        else:
            frame = self.cam.render(self.sim)
            if mode == "depth":
                obs = np.nan_to_num(frame.depth, nan=0.0)
            else:
                pts = frame.points()[frame.object == 0]
                info["points"] = n = min(len(pts), self.max_points)
                if len(pts) > n:
                    keep = np.sort(self.np_random.choice(len(pts), n, replace=False))
                    pts = pts[keep]
                cloud = np.zeros((self.max_points, 3), np.float32)
                cloud[:n] = pts
                pick = (self.pickers.positions - self.cam.position) @ self.cam.rotation
                obs = np.concatenate([cloud.ravel(), pick.ravel().astype(np.float32)])
        return obs, info

    def key_point_state(self) -> np.ndarray:
        """The ``"key_point"`` observation (whatever the mode): the key points, then the pickers,
        ``x, y, z`` each, float32."""
        return np.concatenate(
            [self.sim.positions[self.corners].ravel(), self.pickers.positions.ravel()]
        ).astype(np.float32)

    def render(self):
        if self.render_mode is None:
            gym.logger.warn(
                "render() without a render_mode: pass render_mode='rgb_array' or "
                "'depth_array' to gymnasium.make"
            )
            return None
        frame = self.cam.render(self.sim)
        if self.render_mode == "depth_array":
            return frame.depth
        return render_rgb(frame, self.sim, self.cam, self.pickers)

    def close(self):
        pass
