"""A sweep's spec: a base scene, a grid and random draws over the node's parameters, fixed values,
and a script of grasps and moves; checked whole before anything runs, expanded into runs lazily.

```yaml
scene: hanging_provot     # a scene name or file: the base of every run
duration: 1.0             # simulated seconds per run
frames: 30                # frames per simulated second written to each run's bag (0: no bag)
seed: 1                   # the random draws' seed
set: {allow_unstable: true}          # values every run takes (optional)
grid:                     # the cartesian product; keys are the node's parameter names
  integrator: [symplectic_euler, rk4]
  stiffness.structural: [1.0e+3, 1.0e+4]
random:                   # `samples` draws for each grid point
  samples: 3
  dt: {loguniform: [1.0e-4, 1.0e-3]}
  wind.strength: {uniform: [0.0, 5.0]}
  grasp_x: {uniform: [0.2, 0.8]}     # a script variable: used as $grasp_x below
script:                   # optional, in simulated time
  - {at: 0.1, grasp: {gripper: hand, point: [$grasp_x, 0.0, 0.0], radius: 0.05}}
  - {at: 0.2, move: {gripper: hand, to: [$grasp_x, -0.3, 0.2], duration: 0.5}}
  - {at: 0.8, release: {gripper: hand}}
  - {at: 0.0, move: {collider: ball, to: [0.5, -0.5, -0.3], duration: 1.0}}
```

Every value and range is checked by the schema the node uses
(:data:`~cloth_sim.parameters.SCHEMA`): a grid value, both ends of a uniform or loguniform range
and every choice. Keys of ``grid`` and ``random`` that are not parameters are script variables and
must be used by the script. A bad spec raises :class:`SpecError` naming the key (``grid.dt[2]``,
``random.dt.loguniform``, ``script[1].move.to``) and what is accepted. Combinations (a dt above the
method's stable step, a thickness too large for the cloth) are checked per run, where they make the
run ``refused``.

A run's values are its grid point's values, its draws and, with ``random``, its ``sample`` index;
its id :func:`run_id` is a hash of those alone, and its draws come from a generator seeded by
``seed``, the grid point's index and the sample's: the same spec gives the same runs in the same
order, whatever runs them.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import numbers
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np
import yaml

from ..parameters import SCHEMA, ParameterError

DISTRIBUTIONS = ("uniform", "loguniform", "choice")
TOP_KEYS = ("scene", "duration", "frames", "seed", "set", "grid", "random", "script")
ACTIONS = ("grasp", "move", "release")
#: the most runs one spec may expand to
MAX_RUNS = 10_000_000
_VARIABLE = re.compile(r"^\$([A-Za-z_][A-Za-z0-9_]*)$")
_VARIABLE_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


class SpecError(ValueError):
    """A spec that cannot run; the message names the key and what is accepted."""


@dataclass(frozen=True)
class Spec:
    scene: str
    duration: float
    frames: float
    seed: int
    fixed: dict
    grid: dict
    random: dict
    samples: int
    script: list
    source: str = "<dict>"
    text: str = field(default="", repr=False)

    @property
    def swept(self) -> list[str]:
        """The keys that vary from run to run (grid, then random), in the spec's order."""
        return [*self.grid, *(k for k in self.random)]

    @property
    def grid_points(self) -> int:
        return math.prod(len(v) for v in self.grid.values()) if self.grid else 1

    def __len__(self) -> int:
        return self.grid_points * (self.samples if self.random else 1)

    def runs(self) -> Iterator[dict]:
        """Each run's values (lazily: a 10⁶-run sweep is never a list), in the spec's order."""
        keys = list(self.grid)
        for g, combo in enumerate(itertools.product(*self.grid.values())):
            point = dict(zip(keys, combo))
            if not self.random:
                yield point
                continue
            for s in range(self.samples):
                rng = np.random.default_rng([self.seed, g, s])
                draws = {k: _draw(rng, dist) for k, dist in self.random.items()}
                yield {**point, **draws, "sample": s}

    def values_for(self, run: dict) -> tuple[dict, dict]:
        """``(parameters, variables)`` of a run: the fixed values and the run's, split into the
        node's parameters and the script's variables."""
        merged = {**self.fixed, **{k: v for k, v in run.items() if k != "sample"}}
        params = {k: v for k, v in merged.items() if k in SCHEMA}
        variables = {k: v for k, v in merged.items() if k not in SCHEMA}
        return params, variables


def run_id(run: dict) -> str:
    """A run's stable id: 12 hex digits of the SHA-256 of its values as canonical JSON."""
    text = json.dumps(run, sort_keys=True, separators=(",", ":"), default=_json_default)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def _json_default(x):
    if isinstance(x, np.generic):
        return x.item()
    raise TypeError(f"not JSON: {x!r}")


def _draw(rng, dist: tuple):
    kind, arg = dist
    if kind == "uniform":
        return float(rng.uniform(arg[0], arg[1]))
    if kind == "loguniform":
        return float(math.exp(rng.uniform(math.log(arg[0]), math.log(arg[1]))))
    return arg[int(rng.integers(len(arg)))]


# ----------------------------------------------------------------------------------------- loading
def load_spec(path) -> Spec:
    """Read and check a spec file (:class:`SpecError` naming the file and the key)."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as e:
        raise SpecError(f"{path}: cannot read the spec: {e.strerror or e}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise SpecError(f"{path}: not YAML: {e}") from None
    base = path.parent
    return spec_from_dict(data, source=str(path), text=text, base=base)


def spec_from_dict(data, source: str = "<dict>", text: str = "", base: Path | None = None) -> Spec:
    """Check a spec given as a mapping (what :func:`load_spec` reads)."""

    def fail(key, message):
        # (the schema's own messages name the key already)
        raise SpecError(
            f"{source}: {message}" if message.startswith(key) else f"{source}: {key}: {message}"
        )

    if not isinstance(data, dict):
        fail("spec", f"must be a mapping with keys {', '.join(TOP_KEYS)}, got {_short(data)}")
    unknown = [k for k in data if k not in TOP_KEYS]
    if unknown:
        fail(unknown[0], f"unknown key; accepted keys are {', '.join(TOP_KEYS)}")
    for key in ("scene", "duration"):
        if key not in data:
            fail(key, "missing (required)")
    scene = data["scene"]
    if not isinstance(scene, str) or not scene:
        fail("scene", f"must be a scene name or a scene file, got {_short(scene)}")
    if base is not None and (scene.endswith((".yaml", ".yml")) and not Path(scene).is_absolute()):
        scene = str((base / scene).resolve())
    base_scene = _check_scene(scene, fail)
    duration = _number(data["duration"], "duration", fail, lo=0.0, lo_open=True, hi=1e6, unit="s")
    frames = _number(
        data.get("frames", 0), "frames", fail, lo=0.0, hi=1e4, unit="per simulated second"
    )
    seed = data.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        fail("seed", f"must be an integer >= 0, got {_short(seed)}")

    fixed = _mapping(data.get("set"), "set", fail)
    fixed = {k: _param(f"set.{k}", k, v, fail) for k, v in fixed.items()}
    if "scene" in fixed:
        fail("set.scene", "the base scene is the top-level key scene")

    grid = {}
    for key, values in _mapping(data.get("grid"), "grid", fail).items():
        _key(f"grid.{key}", key, fail)
        if not isinstance(values, list) or not values:
            fail(f"grid.{key}", f"must be a non-empty list of values, got {_short(values)}")
        checked = [_param(f"grid.{key}[{i}]", key, v, fail) for i, v in enumerate(values)]
        seen = [json.dumps(v, sort_keys=True) for v in checked]
        dup = next((i for i, s in enumerate(seen) if s in seen[:i]), None)
        if dup is not None:
            fail(f"grid.{key}[{dup}]", f"{_short(values[dup])} is listed twice")
        grid[key] = checked

    random = _mapping(data.get("random"), "random", fail)
    samples = 0
    draws = {}
    if random:
        samples = random.get("samples")
        if isinstance(samples, bool) or not isinstance(samples, numbers.Integral) or samples < 1:
            fail(
                "random.samples",
                f"must be an integer >= 1 (draws per grid point), got {_short(samples)}",
            )
        for key, dist in random.items():
            if key == "samples":
                continue
            _key(f"random.{key}", key, fail)
            if key in grid:
                fail(f"random.{key}", "is swept by grid already")
            draws[key] = _distribution(key, dist, fail)
        if not draws:
            fail("random", "has samples but nothing to draw")
    for key in [*grid, *draws]:
        if key in fixed:
            fail(f"set.{key}", "is swept by grid or random as well")
        if key == "scene" and key in draws and draws[key][0] != "choice":
            fail("random.scene", "scene can only be drawn by choice")

    variables = {k for k in [*grid, *draws, *fixed] if k not in SCHEMA}
    script = _script(data.get("script"), variables, fail)
    used = {name for event in script for name in _variables_in(event)}
    for name in sorted(variables - used):
        where = "grid" if name in grid else ("random" if name in draws else "set")
        fail(
            f"{where}.{name}",
            f"{name!r} is not a parameter of the node nor a variable the script "
            f"uses (as ${name}); the parameters are {', '.join(sorted(SCHEMA))}",
        )
    if "scene" not in grid and "scene" not in draws:
        _check_colliders(base_scene, script, fail)

    spec = Spec(
        scene=scene,
        duration=duration,
        frames=frames,
        seed=int(seed),
        fixed=fixed,
        grid=grid,
        random=draws,
        samples=int(samples),
        script=script,
        source=source,
        text=text,
    )
    if len(spec) > MAX_RUNS:
        fail("grid", f"the spec expands to {len(spec)} runs; at most {MAX_RUNS} are accepted")
    return spec


def _mapping(x, key, fail) -> dict:
    if x is None:
        return {}
    if not isinstance(x, dict):
        fail(key, f"must be a mapping, got {_short(x)}")
    return x


def _key(where, key, fail) -> None:
    if not isinstance(key, str) or not (key in SCHEMA or _VARIABLE_NAME.match(key)):
        fail(
            where,
            f"{key!r} is not a parameter of the node nor a script variable name (letters, "
            f"digits, _); the parameters are {', '.join(sorted(SCHEMA))}",
        )


def _param(field, name, value, fail):
    """A value of ``name`` at ``field``: checked by the schema (a parameter), or a number or vector
    (a script variable)."""
    if name in SCHEMA:
        try:
            return SCHEMA[name].check(value, field=field)
        except ParameterError as e:
            fail(field, str(e))
    if _is_number(value):
        return float(value)
    if isinstance(value, list) and len(value) == 3 and all(_is_number(v) for v in value):
        return [float(v) for v in value]
    fail(field, f"a script variable must be a finite number or 3 numbers, got {_short(value)}")


def _distribution(key, dist, fail) -> tuple:
    where = f"random.{key}"
    if not isinstance(dist, dict) or len(dist) != 1 or next(iter(dist)) not in DISTRIBUTIONS:
        fail(
            where,
            f"must be one of {{uniform: [lo, hi]}}, {{loguniform: [lo, hi]}}, "
            f"{{choice: [a, b, ...]}}, got {_short(dist)}",
        )
    kind, arg = next(iter(dist.items()))
    where = f"{where}.{kind}"
    if kind == "choice":
        if not isinstance(arg, list) or not arg:
            fail(where, f"must be a non-empty list of values, got {_short(arg)}")
        return kind, [_param(f"{where}[{i}]", key, v, fail) for i, v in enumerate(arg)]
    if key in SCHEMA and SCHEMA[key].type not in (float, int):
        fail(where, f"{key} is {SCHEMA[key].range_text()}: draw it by choice")
    if not isinstance(arg, list) or len(arg) != 2 or not all(_is_number(v) for v in arg):
        fail(where, f"must be [lo, hi], two finite numbers, got {_short(arg)}")
    lo, hi = float(arg[0]), float(arg[1])
    if not lo < hi:
        fail(where, f"needs lo < hi, got [{arg[0]}, {arg[1]}]")
    if kind == "loguniform" and lo <= 0:
        fail(where, f"needs lo > 0 (a log scale), got {arg[0]}")
    if key in SCHEMA:
        spec = SCHEMA[key]
        for i, v in enumerate((lo, hi)):
            try:
                spec.check(int(v) if spec.type is int else v)
            except ParameterError:
                fail(f"{where}[{i}]", f"{arg[i]} is outside {key}'s range: {spec.range_text()}")
        if spec.type is int:
            fail(where, f"{key} is an integer: draw it by choice")
    return kind, [lo, hi]


def _number(x, key, fail, lo=None, hi=None, lo_open=False, unit=""):
    if not _is_number(x):
        fail(key, f"must be a finite number ({unit}), got {_short(x)}")
    x = float(x)
    if (lo is not None and (x <= lo if lo_open else x < lo)) or (hi is not None and x > hi):
        bracket = "(" if lo_open else "["
        fail(key, f"must be in {bracket}{lo:g}, {hi:g}] {unit}, got {x:g}")
    return x


def _is_number(x) -> bool:
    return not isinstance(x, bool) and isinstance(x, numbers.Real) and math.isfinite(float(x))


def _check_scene(scene, fail):
    """The base scene, loaded (it is checked as the node checks a scene file)."""
    from ..scene import SceneError, load_scene

    try:
        return load_scene(scene)
    except (SceneError, ValueError) as e:
        fail("scene", str(e))


def _check_colliders(scene, script, fail) -> None:
    names = [c.name for c in scene.make_colliders()]
    for i, event in enumerate(script):
        move = event.get("move")
        if move and "collider" in move and move["collider"] not in names:
            fail(
                f"script[{i}].move.collider",
                f"{move['collider']!r} is not a collider of scene "
                f"{scene.name}; its colliders are {', '.join(names) or 'none'}",
            )


# ------------------------------------------------------------------------------------------ script
def _script(events, variables: set, fail) -> list:
    if events is None:
        return []
    if not isinstance(events, list):
        fail(
            "script",
            f"must be a list of events ({{at: t, grasp|move|release: ...}}), got {_short(events)}",
        )
    out = []
    for i, ev in enumerate(events):
        where = f"script[{i}]"
        if not isinstance(ev, dict) or "at" not in ev:
            fail(
                where,
                f"must be a mapping with at (s) and one of {', '.join(ACTIONS)}, got {_short(ev)}",
            )
        actions = [k for k in ev if k != "at"]
        if len(actions) != 1 or actions[0] not in ACTIONS:
            fail(
                where,
                f"must hold exactly one of {', '.join(ACTIONS)} beside at, got {_short(list(ev))}",
            )
        at = _scalar(ev["at"], f"{where}.at", variables, fail, lo=0.0)
        kind = actions[0]
        body = ev[kind]
        if not isinstance(body, dict):
            fail(f"{where}.{kind}", f"must be a mapping, got {_short(body)}")
        where = f"{where}.{kind}"
        allowed = {
            "grasp": ("gripper", "point", "radius"),
            "move": ("gripper", "collider", "to", "duration"),
            "release": ("gripper",),
        }[kind]
        extra = [k for k in body if k not in allowed]
        if extra:
            fail(f"{where}.{extra[0]}", f"unknown key; accepted: {', '.join(allowed)}")
        event = {"at": at, kind: {}}
        if kind == "move":
            if ("gripper" in body) == ("collider" in body):
                fail(where, "must name exactly one of gripper or collider")
            target = "gripper" if "gripper" in body else "collider"
            event[kind][target] = _name(body[target], f"{where}.{target}", fail)
            if "to" not in body:
                fail(f"{where}.to", "missing (the position to reach, [x, y, z] m)")
            event[kind]["to"] = _vector(body["to"], f"{where}.to", variables, fail)
            event[kind]["duration"] = _scalar(
                body.get("duration", 0.0), f"{where}.duration", variables, fail, lo=0.0
            )
        else:
            event[kind]["gripper"] = _name(
                body.get("gripper", "gripper"), f"{where}.gripper", fail
            )
            if kind == "grasp":
                if "point" not in body:
                    fail(f"{where}.point", "missing (where to grasp, [x, y, z] m)")
                event[kind]["point"] = _vector(body["point"], f"{where}.point", variables, fail)
                event[kind]["radius"] = _scalar(
                    body.get("radius", 0.05),
                    f"{where}.radius",
                    variables,
                    fail,
                    lo=0.0,
                    lo_open=True,
                )
        out.append(event)
    return out


def _name(x, where, fail) -> str:
    if not isinstance(x, str) or not x:
        fail(where, f"must be a non-empty name, got {_short(x)}")
    return x


def _scalar(x, where, variables, fail, lo=None, lo_open=False):
    if isinstance(x, str):
        m = _VARIABLE.match(x)
        if not m:
            fail(where, f"must be a number or $variable, got {_short(x)}")
        if m.group(1) not in variables:
            fail(where, f"${m.group(1)} is not a key of grid, random or set")
        return x
    return _number(x, where, fail, lo=lo, hi=1e6, lo_open=lo_open)


def _vector(x, where, variables, fail):
    if isinstance(x, str):
        return _scalar(x, where, variables, fail)
    if not isinstance(x, list) or len(x) != 3:
        fail(where, f"must be [x, y, z] (numbers or $variables) or a $variable, got {_short(x)}")
    return [_scalar(v, f"{where}[{i}]", variables, fail, lo=-1e6) for i, v in enumerate(x)]


def _variables_in(obj) -> Iterator[str]:
    if isinstance(obj, str):
        m = _VARIABLE.match(obj)
        if m:
            yield m.group(1)
    elif isinstance(obj, dict):
        for v in obj.values():
            yield from _variables_in(v)
    elif isinstance(obj, list):
        for v in obj:
            yield from _variables_in(v)


def resolve(obj, variables: dict):
    """``obj`` (a script event) with every ``$name`` replaced by its value."""
    if isinstance(obj, str):
        m = _VARIABLE.match(obj)
        return variables[m.group(1)] if m else obj
    if isinstance(obj, dict):
        return {k: resolve(v, variables) for k, v in obj.items()}
    if isinstance(obj, list):
        return [resolve(v, variables) for v in obj]
    return obj


def _short(value) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."
