"""Scripted (oracle) policies for the picker tasks: they read the cloth's corners from the
simulation, so they work with any observation mode. Used by the tests, the README's frames and the
benchmark.

Each is a generator of actions: ``for action in fold(env.unwrapped): env.step(action)``. A policy
moves its pickers through waypoints, each at the pickers' top speed (0.01 m per frame), holding or
not; an env step's action is repeated ``action_repeat`` frames, so the move asked per frame is the
distance left over the frames of one env step.
"""

from __future__ import annotations

import numpy as np


def _go(env, targets, pick: bool, settle: int = 0):
    """Actions taking the pickers to ``targets`` (one row per picker), then ``settle`` more
    steps."""
    targets = np.array([env.pickers.clip(t) for t in np.asarray(targets, float)])
    for _ in range(400):
        left = targets - env.pickers.positions
        if np.abs(left).max() < 1e-6:
            break
        yield _action(env, np.clip(left / env.action_repeat, -0.01, 0.01), pick)
    for _ in range(settle):
        yield _action(env, np.zeros_like(targets), pick)


def _action(env, delta, pick: bool) -> np.ndarray:
    a = np.zeros((env.num_picker, 4), np.float32)
    a[:, :3] = delta
    a[:, 3] = 1.0 if pick else 0.0
    return a.ravel()


def flatten(env):
    """Pick the two corners of an edge (the pair farthest apart of the cloth's four corners that
    share an edge), then :func:`_lay_down`."""
    x = env.sim.positions
    c = env.corners
    # the four edges: their corners, their rest length and the other side's
    w, h = env.spacing * (env.cols - 1), env.spacing * (env.rows - 1)
    edges = [(c[0], c[2], w, h), (c[1], c[3], w, h), (c[0], c[1], h, w), (c[2], c[3], h, w)]
    yield from _lay_down(env, *max(edges, key=lambda e: np.linalg.norm(x[e[0], :2] - x[e[1], :2])))


def flatten_garment(
    env,
    a: str = "hem_left",
    b: str = "hem_right",
    then=(("sleeve_left_bottom", "sleeve_right_bottom"), ("shoulder_left", "shoulder_right")),
):
    """A garment by two of its landmarks (the hem's corners: one vertex of both panels each),
    :func:`_lay_down` (spread to their distance laid flat, the garment trailing its length from
    them); then each pair of ``then`` picked and placed where the garment laid flat has it, seen
    from where the first two now lie (the sleeves, then the shoulders)."""
    marks = env.model.meta["landmarks"]
    flat = env.flat_positions()
    i, j = marks[a], marks[b]
    edge = float(np.linalg.norm(flat[i, :2] - flat[j, :2]))
    d = (flat[j, :2] - flat[i, :2]) / edge
    across = flat[:, :2] @ np.array([-d[1], d[0]])  # how far the garment reaches from the line ab
    length = float(np.abs(across - across[i]).max())
    yield from _lay_down(env, i, j, edge, length)
    for pair in then:
        x = env.sim.positions
        # the flat layout placed on the line a–b as it lies now, the rest of it on the side away
        # from where the garment lies
        now = x[j, :2] - x[i, :2]
        now /= max(np.linalg.norm(now), 1e-9)
        rot = np.array([[now[0], -now[1]], [now[1], now[0]]]) @ np.array(
            [[d[0], d[1]], [-d[1], d[0]]]
        )
        centre = x[:, :2].mean(axis=0)
        side = np.sign((centre - x[i, :2]) @ np.array([-now[1], now[0]])) or 1.0
        flip = np.sign((flat[:, :2].mean(axis=0) - flat[i, :2]) @ np.array([-d[1], d[0]])) or 1.0
        if side != flip:  # mirrored across the line a–b
            rot = rot @ (np.eye(2) - 2 * np.outer([-d[1], d[0]], [-d[1], d[0]]))
        ks = [marks[n] for n in pair]
        goal = [(rot @ (flat[k, :2] - flat[i, :2])) + x[i, :2] for k in ks]
        low = env.pickers.low[2] + 0.02
        yield from _go(env, x[ks], pick=False)
        yield from _go(env, x[ks], pick=True, settle=1)
        up = env.pickers.positions.copy()
        up[:, 2] = low + 0.1
        yield from _go(env, up, pick=True)
        yield from _go(env, [[*g, low + 0.1] for g in goal], pick=True)
        yield from _go(env, [[*g, low] for g in goal], pick=True, settle=1)
        yield from _go(env, env.pickers.positions, pick=False, settle=2)


def _lay_down(env, a: int, b: int, edge: float, length: float):
    """Pick particles ``a`` and ``b``, lift them until the cloth hangs, pull them apart to
    ``edge``, then drag them across the floor away from where the cloth hangs while lowering,
    about ``length``, and let go: the cloth is laid down flat behind them."""
    x = env.sim.positions
    yield from _go(env, [x[a], x[b]], pick=False)
    yield from _go(env, [x[a], x[b]], pick=True, settle=1)
    top = env.pickers.high[2]
    p = env.pickers.positions
    yield from _go(env, [[p[0, 0], p[0, 1], top], [p[1, 0], p[1, 1], top]], pick=True)
    mid = env.pickers.positions.mean(axis=0)
    d = env.pickers.positions[1, :2] - env.pickers.positions[0, :2]
    d = d / max(np.linalg.norm(d), 1e-9)
    half = np.array([*d, 0.0]) * edge / 2
    yield from _go(env, [mid - half, mid + half], pick=True, settle=4)  # spread, still
    # drag away from the cloth's centre, lowering, so it lays down behind the pickers
    centre = env.sim.positions[:, :2].mean(axis=0)
    away = np.array([-d[1], d[0]])
    if away @ (mid[:2] - centre) < 0:
        away = -away
    p = env.pickers.positions.copy()
    low = env.pickers.low[2] + 0.02
    # first drag the hanging cloth's lower edge along the floor, then lower as they go, the cloth
    # trailing behind
    for f, z in ((0.2, 0.3), (0.5, 0.05), (1.1, 0.0)):
        yield from _go(
            env,
            [[*(p[i, :2] + away * length * f), low + (p[i, 2] - low) * z] for i in range(2)],
            pick=True,
        )
    yield from _go(env, env.pickers.positions, pick=True, settle=2)
    yield from _go(env, env.pickers.positions, pick=False, settle=3)


def fold(env):
    """Fold the left half (columns ``< cols/2``) onto the right: pick the left edge's two corners,
    carry them over in a half circle about the middle to 3 cm above the right edge's corners and
    let go there."""
    x = env.sim.positions
    c = env.corners
    yield from _carry_over(env, x[[c[0], c[1]]], x[[c[2], c[3]]])


def fold_garment(env):
    """The garment's fold (:meth:`~cloth_sim.envs.garments.TshirtFoldEnv.folds`), fold by fold:
    the fold's two landmarks picked and carried over its line to their mirror images, where the
    garment lies now (the flat layout fitted to its landmarks)."""
    marks = env.model.meta["landmarks"]
    every = list(marks.values())
    flat = env.flat_positions()[every, :2]
    for (a, b), point, normal in env.folds():
        ks = [marks[a], marks[b]]
        x = env.sim.positions
        rot, shift = rigid_fit(flat, x[every, :2])
        p, n = rot @ point + shift, rot @ normal
        src = x[ks]
        dst = src.copy()
        dst[:, :2] -= 2 * np.outer((src[:, :2] - p) @ n, n)
        yield from _carry_over(env, src, dst)


def rigid_fit(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rotation and shift taking the 2-D points ``a`` nearest ``b`` (least squares: Kabsch)."""
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    d = np.sign(np.linalg.det(u @ vt)) or 1.0
    rot = (u @ np.diag([1.0, d]) @ vt).T
    return rot, cb - rot @ ca


def _carry_over(env, src, dst):
    """Pick the particles at ``src`` (one row per picker), carry them over in a half circle about
    the crease midway to ``dst`` (the held edge's path when the cloth folds without stretching or
    sliding), to 3 cm above ``dst``, and let go there."""
    yield from _go(env, src, pick=False)
    yield from _go(env, src, pick=True, settle=1)
    crease = (src + dst) / 2
    for angle in np.linspace(np.pi / 6, np.pi, 6):
        yield from _go(
            env,
            crease
            + (src - crease) * np.cos(angle)
            + (0.0, 0.0, np.linalg.norm(src - crease, axis=1).mean() * np.sin(angle)),
            pick=True,
        )
    yield from _go(env, dst + (0.0, 0.0, 0.03), pick=True, settle=1)
    yield from _go(env, env.pickers.positions, pick=False, settle=3)


#: each task's scripted policy (the picker action mode's), by the task's name (``env.task``)
SCRIPTED = {
    "ClothFlatten": flatten,
    "ClothFold": fold,
    "TshirtFlatten": flatten_garment,
    "TshirtFold": fold_garment,
}
