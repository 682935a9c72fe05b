"""The independent crossing check: where a particle passes through a triangle of the cloth between
two states (benchmarks and tests count crossings with it; it shares no code with the simulator's
collision handling).

Every particle moves on a straight path between the states and so does every triangle's corner; a
particle ``p`` not a corner of triangle ``abc`` crosses it when the coplanarity cubic ``f(s) = (p −
a)·((b − a) × (c − a))`` has a root in ``[0, 1]`` at which ``p`` lies inside the triangle. The
cubic's coefficients come from four samples, its real roots from monotone brackets (split at the
roots of ``f'``) and bisection. Candidate pairs are those whose swept boxes overlap, found with
SciPy's k-d tree over the boxes' centres.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def _overlapping(x0, x1, tris):
    """``(P, T)``: the (particle, triangle) pairs whose boxes over the motion overlap, the particle
    not a corner."""
    lo_p, hi_p = np.minimum(x0, x1), np.maximum(x0, x1)
    lo_t, hi_t = lo_p[tris].min(axis=1), hi_p[tris].max(axis=1)
    c_p, c_t = 0.5 * (lo_p + hi_p), 0.5 * (lo_t + hi_t)
    r_p = 0.5 * np.linalg.norm(hi_p - lo_p, axis=1)
    r_t = 0.5 * np.linalg.norm(hi_t - lo_t, axis=1)
    # two boxes overlap only if their centres are within the sum of their half-diagonals
    near = cKDTree(c_t).query_ball_point(c_p, r_p + float(r_t.max()) + 1e-12)
    P = np.repeat(np.arange(len(x0)), [len(k) for k in near])
    T = np.fromiter((t for k in near for t in k), dtype=np.int64, count=len(P))
    keep = (
        np.all(lo_t[T] <= hi_p[P], axis=1)
        & np.all(hi_t[T] >= lo_p[P], axis=1)
        & np.all(tris[T] != P[:, None], axis=1)
    )
    return P[keep], T[keep]


def crossings(x0, x1, tris) -> list[tuple[int, int]]:
    """Pairs (particle, triangle), sorted, the particle not a corner, where the particle passes
    through the triangle between positions ``x0`` and ``x1`` (module docstring)."""
    x0, x1 = np.asarray(x0, dtype=np.float64), np.asarray(x1, dtype=np.float64)
    tris = np.asarray(tris, dtype=np.int64).reshape(-1, 3)
    d = x1 - x0
    P, T = _overlapping(x0, x1, tris)
    if len(P) == 0:
        return []
    A, B, C = (tris[T, k] for k in range(3))

    def pos(i, s):
        return x0[i] + s[:, None] * d[i]

    def f(s):
        p, a, b, c = pos(P, s), pos(A, s), pos(B, s), pos(C, s)
        return np.einsum("ij,ij->i", p - a, np.cross(b - a, c - a))

    ones = np.ones(len(P))
    ss = np.array([0.0, 1 / 3, 2 / 3, 1.0])
    coef = np.linalg.solve(np.vander(ss, 4), np.stack([f(s * ones) for s in ss]))  # c3, c2, c1, c0
    c3, c2, c1 = coef[0], coef[1], coef[2]
    # critical points: 3 c3 s² + 2 c2 s + c1 = 0, clipped into [0, 1]
    qa, qb, qc = 3 * c3, 2 * c2, c1
    disc = qb * qb - 4 * qa * qc
    with np.errstate(divide="ignore", invalid="ignore"):
        sq = np.sqrt(np.maximum(disc, 0))
        r1 = np.where(qa != 0, (-qb - sq) / (2 * qa), np.where(qb != 0, -qc / qb, 0.0))
        r2 = np.where(qa != 0, (-qb + sq) / (2 * qa), r1)
    r1 = np.where(np.isfinite(r1) & (disc >= 0), r1, 0.0)
    r2 = np.where(np.isfinite(r2) & (disc >= 0), r2, 0.0)
    k1, k2 = np.clip(np.minimum(r1, r2), 0, 1), np.clip(np.maximum(r1, r2), 0, 1)
    found = set()
    all_P, all_A, all_B, all_C, all_T = P, A, B, C, T
    c0 = coef[3]

    def cubic(s, k):
        return ((c3[k] * s + c2[k]) * s + c1[k]) * s + c0[k]

    every = np.arange(len(P))
    for lo, hi in ((0 * ones, k1), (k1, k2), (k2, ones)):
        bracket = np.flatnonzero((cubic(lo, every) * cubic(hi, every) <= 0) & (hi >= lo))
        P, A, B, C, T = (
            all_P[bracket],
            all_A[bracket],
            all_B[bracket],
            all_C[bracket],
            all_T[bracket],
        )
        lo, hi = lo[bracket], hi[bracket]
        if len(P) == 0:
            continue
        flo = cubic(lo, bracket)
        for _ in range(50):  # bisection on each monotone bracket
            mid = 0.5 * (lo + hi)
            fm = cubic(mid, bracket)
            left = flo * fm <= 0
            hi = np.where(left, mid, hi)
            lo = np.where(left, lo, mid)
            flo = np.where(left, flo, fm)
        s = 0.5 * (lo + hi)
        p, a, b, c = pos(P, s), pos(A, s), pos(B, s), pos(C, s)
        v0, v1, v2 = b - a, c - a, p - a
        d00, d01, d11 = (v0 * v0).sum(1), (v0 * v1).sum(1), (v1 * v1).sum(1)
        d20, d21 = (v2 * v0).sum(1), (v2 * v1).sum(1)
        den = d00 * d11 - d01 * d01
        with np.errstate(divide="ignore", invalid="ignore"):
            bv = (d11 * d20 - d01 * d21) / den
            bw = (d00 * d21 - d01 * d20) / den
        inside = (den > 0) & (bv >= 0) & (bw >= 0) & (bv + bw <= 1)
        found.update(zip(P[inside].tolist(), T[inside].tolist()))
    return sorted(found)
