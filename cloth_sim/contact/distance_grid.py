"""A mesh collider's signed distance baked once onto a regular grid in its own frame, and read by
trilinear interpolation: how a device without the mesh's tree and feature cells (the CUDA backend,
:mod:`cloth_sim.cuda`) asks a mesh's distance and normal at the cost of a primitive's.

The grid's nodes cover the mesh's box grown by a **band** on every side, ``cell`` apart; each
node holds the exact distance of :func:`~cloth_sim.contact.collider_kernels.mesh_sdf` there
(signed for a closed mesh, unsigned for an open one, :mod:`.triangle_meshes`). A point inside
the grid reads the trilinear interpolation of its cell's eight nodes, and its normal is that
interpolant's gradient, normalised.

- **Over a face** the distance is the face's plane at all eight nodes, and trilinear
  interpolation reproduces an affine function: the exact distance and the face's normal, to
  rounding. A cloth lying on a mesh's face is where it lies on the mesh itself.
- **Near an edge, a corner or a crease** the interpolant is within a fraction of a cell of the
  exact distance. Outside a convex edge, where the distance is convex, it is above it: a 0.4 ×
  0.4 × 0.1 m box of 12 triangles, cells of 3.1 mm, 1.0 mm at most over 20,000 points within the
  band.
- **Outside the grid** a point is at least the band plus its distance from the grid's box from
  the mesh (a segment from it to its nearest point on the mesh crosses the grid's boundary, every
  point of which is at least the band from the mesh's box). That lower bound is its answer, with
  the box's outward normal. The band is wider than the thickness the cloth keeps, so a point the
  grid does not cover touches nothing, and a march along a path (sphere tracing) stays
  conservative there.

Sizes (:func:`cell_for`): cells of half the thickness, at most :data:`MAX_NODES_ALONG` nodes along
the mesh's longest side and :data:`MAX_NODES` in all (the cell grows until both hold); the band is
:data:`BAND_THICKNESS` thicknesses and at least :data:`BAND_CELLS` cells. A grid is baked once per
mesh, cell and band (:func:`grid_for` keeps it while the mesh lives).

Written here rather than taken from a library (trimesh's and Open3D's signed distance queries, or
``scipy.ndimage`` for the interpolation): the nodes must hold this package's own distances (its
closed and open meshes, its signs), and the device reads the interpolation in the same arithmetic
as :meth:`DistanceGrid.at`, which the tests hold it to.
"""

from __future__ import annotations

import math
import weakref
from typing import NamedTuple

import numba
import numpy as np

from ..kernel_cache import keep_true
from . import triangle_meshes
from .collider_kernels import mesh_sdf

#: nodes along the mesh's longest side at most (with the band)
MAX_NODES_ALONG = 160
#: nodes in a grid at most
MAX_NODES = 1 << 22
#: the band the grid covers beyond the mesh's box: this many thicknesses, and at least
#: :data:`BAND_CELLS` cells
BAND_THICKNESS, BAND_CELLS = 3.0, 2


class DistanceGrid(NamedTuple):
    """A mesh's baked distance: the first node ``origin`` (3, in the mesh's frame), the nodes'
    spacing ``cell`` (m), the ``band`` (m) the grid reaches beyond the mesh's box, and the
    distances ``values`` at the nodes, ``(nx, ny, nz)``."""

    origin: np.ndarray
    cell: float
    band: float
    values: np.ndarray

    def at(self, points):
        """The distance and outward unit normal at ``(k, 3)`` points in the mesh's frame, as the
        device reads them (module docstring): ``(d (k,), n (k, 3))``."""
        p = np.atleast_2d(np.asarray(points, np.float64))
        d = np.empty(len(p))
        n = np.empty((len(p), 3))
        for r, (qx, qy, qz) in enumerate(p):
            d[r], n[r, 0], n[r, 1], n[r, 2] = grid_distance(self, qx, qy, qz)
        return d, n


def cell_for(mesh: triangle_meshes.TriangleMesh, thickness: float) -> tuple[float, float]:
    """``(cell, band)`` of ``mesh``'s grid for a cloth that keeps ``thickness`` from it (module
    docstring)."""
    span = mesh.hi[0] - mesh.lo[0]
    longest = max(float(span.max()), 1e-9)
    cell = 0.5 * thickness
    while True:
        band = max(BAND_THICKNESS * thickness, BAND_CELLS * cell)
        dims = np.ceil((span + 2.0 * band) / cell) + 1
        if dims.max() <= MAX_NODES_ALONG and np.prod(dims) <= MAX_NODES:
            return cell, band
        cell = max(1.25 * cell, longest / (MAX_NODES_ALONG - 1 - 2 * BAND_CELLS))


def bake(mesh: triangle_meshes.TriangleMesh, cell: float, band: float) -> DistanceGrid:
    """``mesh``'s distances at the nodes ``cell`` apart over its box grown by ``band``."""
    lo, hi = mesh.lo[0], mesh.hi[0]
    origin = lo - band
    dims = (np.ceil((hi - lo + 2.0 * band) / cell) + 1).astype(np.int64)
    axes = [origin[k] + cell * np.arange(dims[k]) for k in range(3)]
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    cutoff = band + math.sqrt(3.0) * cell
    values = _sample(np.ascontiguousarray(nodes), triangle_meshes.pack([mesh]), cutoff)
    return DistanceGrid(origin, float(cell), float(band), values.reshape(tuple(dims)))


@numba.njit(cache=True, parallel=True)
def _sample(nodes, bank, cutoff):
    """The mesh's (index 0 of ``bank``, in its own frame) distance at each node, at most
    ``cutoff``: a node farther outside is answered ``cutoff`` without the rest of the walk. Every
    cell holding a point within the band has its eight nodes within ``band + √3·cell`` of the
    mesh, so there the values are exact; elsewhere they are lower, and an answer there a lower
    bound still. A 0.4 × 0.4 × 0.1 m box of 12 triangles at 3.1 mm cells (830,000 nodes): 35 ms
    on two cores, where every node's exact distance, one core, took 2.4 s."""
    pos, rot, geo = np.zeros((1, 3)), np.zeros((1, 3, 3)), np.zeros((1, 4))
    for k in range(3):
        rot[0, k, k] = 1.0
    reals, ints, starts = bank
    out = np.empty(nodes.shape[0])
    for q in numba.prange(nodes.shape[0]):
        out[q] = mesh_sdf(
            pos, rot, geo, 0, nodes[q, 0], nodes[q, 1], nodes[q, 2], reals, ints, starts, cutoff
        )[0]
    return out


#: grids baked so far: per mesh (while it lives), per (cell, band)
_BAKED: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def grid_for(mesh: triangle_meshes.TriangleMesh, thickness: float) -> DistanceGrid:
    """``mesh``'s grid for ``thickness`` (:func:`cell_for`), baked on first use."""
    key = cell_for(mesh, thickness)
    grids = _BAKED.setdefault(mesh, {})
    if key not in grids:
        grids[key] = bake(mesh, *key)
    return grids[key]


def grid_distance(grid: DistanceGrid, qx: float, qy: float, qz: float):
    """The distance and normal at ``q`` (mesh frame) of one grid: ``(d, nx, ny, nz)``, in the
    arithmetic of the device's :func:`cloth_sim.cuda.kernels.mesh_at` (which calls the same
    :func:`trilinear` and :func:`outside`)."""
    v = grid.values
    nx, ny, nz = v.shape
    ox, oy, oz = grid.origin
    h = grid.cell
    fx, fy, fz = (qx - ox) / h, (qy - oy) / h, (qz - oz) / h
    if not (0.0 <= fx <= nx - 1 and 0.0 <= fy <= ny - 1 and 0.0 <= fz <= nz - 1):
        return outside((ox, oy, oz, h, grid.band), nx, ny, nz, qx, qy, qz)
    i, j, k = min(int(fx), nx - 2), min(int(fy), ny - 2), min(int(fz), nz - 2)
    corners = (
        v[i, j, k],
        v[i + 1, j, k],
        v[i, j + 1, k],
        v[i + 1, j + 1, k],
        v[i, j, k + 1],
        v[i + 1, j, k + 1],
        v[i, j + 1, k + 1],
        v[i + 1, j + 1, k + 1],
    )
    return trilinear(corners, fx - i, fy - j, fz - k, h)


@numba.njit(cache=True, inline="always")
def trilinear(c, tx, ty, tz, h):
    """The interpolation of a cell's eight nodes ``c`` (x fastest, then y, then z) at ``(tx, ty,
    tz)`` in ``[0, 1]³`` and its gradient normalised (the cell ``h`` apart): ``(d, nx, ny, nz)``;
    a zero gradient gives the normal ``(0, 0, 0)``."""
    c000, c100, c010, c110, c001, c101, c011, c111 = c
    sx, sy, sz = 1.0 - tx, 1.0 - ty, 1.0 - tz
    d = sz * (sy * (sx * c000 + tx * c100) + ty * (sx * c010 + tx * c110)) + tz * (
        sy * (sx * c001 + tx * c101) + ty * (sx * c011 + tx * c111)
    )
    gx = sz * (sy * (c100 - c000) + ty * (c110 - c010)) + tz * (
        sy * (c101 - c001) + ty * (c111 - c011)
    )
    gy = sz * (sx * (c010 - c000) + tx * (c110 - c100)) + tz * (
        sx * (c011 - c001) + tx * (c111 - c101)
    )
    gz = sy * (sx * (c001 - c000) + tx * (c101 - c100)) + ty * (
        sx * (c011 - c010) + tx * (c111 - c110)
    )
    g = math.sqrt(gx * gx + gy * gy + gz * gz)
    if not g > 1e-12 * h:
        return d, 0.0, 0.0, 0.0
    return d, gx / g, gy / g, gz / g


@numba.njit(cache=True, inline="always")
def outside(box, nx, ny, nz, qx, qy, qz):
    """A point ``q`` outside the grid (``box``: its first node, cell and band; ``nx, ny, nz``
    its nodes along each axis): the band plus its distance from the grid's box, with the box's
    outward normal there (module docstring), ``(d, nx, ny, nz)``."""
    ox, oy, oz, h, band = box
    ex, ey, ez = 0.5 * h * (nx - 1), 0.5 * h * (ny - 1), 0.5 * h * (nz - 1)
    ax, ay, az = abs(qx - (ox + ex)) - ex, abs(qy - (oy + ey)) - ey, abs(qz - (oz + ez)) - ez
    px, py, pz = max(ax, 0.0), max(ay, 0.0), max(az, 0.0)
    r = math.sqrt(px * px + py * py + pz * pz)
    if not r > 0.0:
        return band, 0.0, 0.0, 0.0
    return (
        band + r,
        math.copysign(px, qx - (ox + ex)) / r,
        math.copysign(py, qy - (oy + ey)) / r,
        math.copysign(pz, qz - (oz + ez)) / r,
    )


def pack_grids(grids, real) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``grids`` as the device reads them: per grid ``box`` (origin x, y, z, cell, band) in
    ``real``, ``dims`` (nodes along x, y, z, its first value in ``values``) int32, and every
    grid's values one after another (x slowest, z fastest) in ``real``; one empty grid where
    there are none."""
    box = np.zeros((max(1, len(grids)), 5), real)
    dims = np.zeros((max(1, len(grids)), 4), np.int32)
    chunks, start = [], 0
    for m, g in enumerate(grids):
        box[m, :3], box[m, 3], box[m, 4] = g.origin, g.cell, g.band
        dims[m, :3], dims[m, 3] = g.values.shape, start
        chunks.append(g.values.ravel())
        start += g.values.size
    values = np.concatenate(chunks).astype(real) if chunks else np.zeros(1, real)
    return box, dims, values


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
