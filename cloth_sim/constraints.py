"""Position constraints applied after each step: Provot's super-elasticity correction.

Provot (1995) keeps structural and shear springs from stretching beyond a critical deformation rate
``τc``: after the particles move, every spring longer than ``(1 + τc)·L`` is shortened to exactly
that length by moving both ends equally along the spring, or only the free end when the other is
pinned. One pass visits every limited spring once (Gauss–Seidel), so a pass can stretch a spring an
earlier correction had fixed. Springs are visited outward from the pins (by graph distance), so one
pass carries a correction from a pin to the far edge, as the weight hangs; passes stop early once
one corrects nothing.
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import shortest_path

from .forces import spring_vector

#: Passes per step unless the simulator is told otherwise.
DEFAULT_STRAIN_LIMIT_PASSES = 20
#: Strain above ``τc`` that a pass tolerates (so passes stop once nothing is meaningfully too long).
STRAIN_LIMIT_TOLERANCE = 1e-4


@numba.njit(cache=True)
def provot_pass(x, springs, rest, tau, tol, pinned):
    """One Gauss–Seidel pass of Provot's correction; returns how many springs it shortened.

    A spring counts as too long when its strain exceeds ``tau + tol``; it is then shortened to
    strain ``tau`` exactly."""
    corrected = 0
    for s in range(springs.shape[0]):
        i = springs[s, 0]
        j = springs[s, 1]
        pi, pj = pinned[i], pinned[j]
        if pi and pj:
            continue
        dx, dy, dz, l = spring_vector(x, i, j)
        lmax = (1.0 + tau) * rest[s]
        if l <= lmax + tol * rest[s]:
            continue
        corrected += 1
        excess = (l - lmax) / l  # fraction of the spring vector to remove
        if pi:
            wi, wj = 0.0, 1.0
        elif pj:
            wi, wj = 1.0, 0.0
        else:
            wi, wj = 0.5, 0.5
        x[i, 0] += wi * excess * dx
        x[i, 1] += wi * excess * dy
        x[i, 2] += wi * excess * dz
        x[j, 0] -= wj * excess * dx
        x[j, 1] -= wj * excess * dy
        x[j, 2] -= wj * excess * dz
    return corrected


class StrainLimit:
    """Provot's correction over a model's strain-limited springs."""

    def __init__(self, model, tau: float, passes: int = DEFAULT_STRAIN_LIMIT_PASSES):
        if not (np.isfinite(tau) and tau >= 0):
            raise ValueError(f"strain_limit must be a finite number >= 0 (or None), got {tau}")
        if int(passes) < 1:
            raise ValueError(f"strain_limit_passes must be >= 1, got {passes}")
        self.tau = float(tau)
        self.passes = int(passes)
        sel = np.flatnonzero(model.strain_limited)
        sel = sel[_outward_order(model, model.springs[sel])]
        self.springs = np.ascontiguousarray(model.springs[sel])
        self.rest = np.ascontiguousarray(model.rest_lengths[sel])
        self.pinned = np.ascontiguousarray(model.pinned)
        self.last_passes = 0

    def apply(self, x: np.ndarray) -> int:
        """Correct ``x`` in place; returns the number of passes that changed something."""
        used = 0
        for _ in range(self.passes):
            if provot_pass(x, self.springs, self.rest, self.tau, STRAIN_LIMIT_TOLERANCE,
                           self.pinned) == 0:
                break
            used += 1
        self.last_passes = used
        return used


def _outward_order(model, springs) -> np.ndarray:
    """Order of ``springs`` by hop distance of their nearer end from the nearest pin (stable)."""
    pins = np.flatnonzero(model.pinned)
    if len(pins) == 0 or len(springs) == 0:
        return np.arange(len(springs))
    n = model.n_particles
    s = model.springs
    graph = sp.csr_matrix((np.ones(len(s)), (s[:, 0], s[:, 1])), shape=(n, n))
    hops = shortest_path(graph, directed=False, unweighted=True, indices=pins).min(axis=0)
    near = np.minimum(hops[springs[:, 0]], hops[springs[:, 1]])
    far = np.maximum(hops[springs[:, 0]], hops[springs[:, 1]])
    return np.lexsort((far, near))
