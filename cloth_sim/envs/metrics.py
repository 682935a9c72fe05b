"""The tasks' measures, as SoftGym defines them (Lin et al. 2020), as pure functions of positions.

* :func:`covered_area` — ClothFlatten's performance: the area of the ground the cloth covers, seen
  from above. SoftGym discretises the bounding box of the particles into 100 × 100 cells and marks
  every cell within a particle's radius of a particle; so does this (the radius: half the grid
  spacing, so a flat grid covers its bounding box, ``(cols − 1)·s × (rows − 1)·s``).
* :func:`fold_distance` — ClothFold's performance: minus the mean distance between each particle of
  one half and its mirror image in the other, minus 1.2 × the mean distance the other half moved.
* :func:`mean_distance` — ClothDrop's: minus the mean distance to the target (flat) positions.
* :func:`shape_distance` — TshirtFold's: how far the distances between a garment's landmarks, pair
  by pair, are from those of the garment folded as asked (blind to where it lies and which way it
  faces).
* :func:`normalized` — ``(p − p₀) / (p_best − p₀)``: 0 at the start, 1 at the best possible.
"""

from __future__ import annotations

import numpy as np

CELLS = 100


def covered_area(positions: np.ndarray, radius: float, cells: int = CELLS) -> float:
    """Area (m²) of the union of the axis-aligned squares of half-width ``radius`` about each
    particle's ``(x, y)``, measured on a ``cells × cells`` grid over the particles' bounding box (a
    cell counts when its index range is within ``radius`` of a particle, SoftGym's rounding)."""
    xy = np.asarray(positions, float)[:, :2]
    lo = xy.min(axis=0)
    span = (xy.max(axis=0) - lo) / cells
    span[span <= 0] = radius * 2 / cells or 1.0
    off = xy - lo
    a = np.clip(np.round((off - radius) / span).astype(np.int64), 0, cells)
    b = np.clip(np.round((off + radius) / span).astype(np.int64), 0, cells)
    # a 2-D difference array: +1 at (a0, a1), −1 at (b0, a1) and (a0, b1), +1 at (b0, b1)
    diff = np.zeros((cells + 1, cells + 1), np.int64)
    np.add.at(diff, (a[:, 0], a[:, 1]), 1)
    np.add.at(diff, (b[:, 0], a[:, 1]), -1)
    np.add.at(diff, (a[:, 0], b[:, 1]), -1)
    np.add.at(diff, (b[:, 0], b[:, 1]), 1)
    covered = np.cumsum(np.cumsum(diff, axis=0), axis=1)[:cells, :cells] > 0
    return float(covered.sum() * span[0] * span[1])


def fold_groups(rows: int, cols: int) -> tuple[np.ndarray, np.ndarray]:
    """ClothFold's halves of a ``rows × cols`` grid: group a, the columns left of the middle, and
    group b, their mirror images (column ``cols − 1 − j`` for column ``j``), in matching order."""
    grid = np.arange(rows * cols).reshape(rows, cols)
    half = cols // 2
    return grid[:, :half].ravel(), grid[:, ::-1][:, :half].ravel()


def fold_distance(positions, initial, group_a, group_b) -> tuple[float, float, float]:
    """``(performance, group distance, fixation distance)``: the group distance is the mean of
    ``|x_a − x_b|`` over the mirrored pairs, the fixation distance the mean of ``|x_b − x_b(0)|``,
    and the performance ``−group − 1.2·fixation``."""
    x = np.asarray(positions, float)
    group = float(np.mean(np.linalg.norm(x[group_a] - x[group_b], axis=1)))
    fixation = float(np.mean(np.linalg.norm(x[group_b] - np.asarray(initial)[group_b], axis=1)))
    return -group - 1.2 * fixation, group, fixation


def mean_distance(positions, target) -> float:
    """Mean distance of the particles from their ``target`` positions (m)."""
    return float(np.mean(np.linalg.norm(np.asarray(positions, float) - target, axis=1)))


def shape_distance(positions, target) -> float:
    """Mean over the pairs ``(i, j)`` of points of ``| |x_i − x_j| − |t_i − t_j| |`` (m): 0 when
    ``positions`` are ``target`` moved rigidly (or mirrored), whatever the frame."""
    x, t = np.asarray(positions, float), np.asarray(target, float)
    i, j = np.triu_indices(len(t), 1)
    return float(
        np.mean(np.abs(np.linalg.norm(x[i] - x[j], axis=1) - np.linalg.norm(t[i] - t[j], axis=1)))
    )


def normalized(performance: float, initial: float, best: float) -> float:
    """``(performance − initial) / (best − initial)`` (0 when ``best == initial``)."""
    return 0.0 if best == initial else float((performance - initial) / (best - initial))
