"""A mesh's distance baked onto a grid (what the CUDA device reads for a mesh collider), against
the exact mesh queries and the closed forms of a box and a plate: exact over a face, within a
fraction of a cell near edges and corners, a lower bound outside the grid, and its sizes."""

import math

import numpy as np
import pytest

from cloth_sim.contact import distance_grid as dg
from cloth_sim.contact.colliders import Mesh
from cloth_sim.contact.triangle_meshes import box_triangles

TAU = 0.005


def box_distance(p, half):
    """The box's signed distance, its closed form."""
    q = np.abs(p) - half
    out = np.linalg.norm(np.maximum(q, 0.0), axis=1)
    return out + np.minimum(np.max(q, axis=1), 0.0)


@pytest.fixture(scope="module")
def box():
    half = np.array([0.1, 0.08, 0.03])
    mesh = Mesh(box_triangles(half))
    return half, mesh, dg.grid_for(mesh.mesh, TAU)


def test_over_a_face_the_grid_is_the_face(box):
    """Above and just inside the top face, away from its edges, the interpolation of the plane's
    nodes is the plane: the exact distance and the face's normal, to rounding."""
    half, _, grid = box
    rng = np.random.default_rng(1)
    p = np.c_[
        rng.uniform(-0.08, 0.08, 400),
        rng.uniform(-0.06, 0.06, 400),
        rng.uniform(half[2] - 0.004, half[2] + 0.012, 400),
    ]
    d, n = grid.at(p)
    assert np.max(np.abs(d - box_distance(p, half))) < 1e-15
    assert np.max(np.abs(n - (0.0, 0.0, 1.0))) < 1e-12


def test_within_the_band_the_grid_is_within_a_fraction_of_a_cell(box):
    """Everywhere within the band of the box (edges, corners, inside), the grid is within 0.35 of a
    cell of the exact distance (0.15 outside, 0.31 inside, measured), and more than a cell
    outside, its normal within 0.4 rad of the exact one (0.36 measured at one to two cells from an
    edge or a corner, where the exact normal turns by about a radian over a cell; 0.15 beyond
    three cells); the mesh's own query is the closed form."""
    half, mesh, grid = box
    rng = np.random.default_rng(2)
    p = rng.uniform(-1.0, 1.0, (4000, 3)) * (half + grid.band)
    exact = box_distance(p, half)
    assert np.max(np.abs(mesh.signed_distance(p) - exact)) < 1e-12
    d, n = grid.at(p)
    near = (exact < grid.band) & (exact > -grid.band)
    assert near.sum() > 1000
    assert np.max(np.abs(d - exact)[near]) < 0.35 * grid.cell
    eps = 1e-6
    g = np.stack(
        [(box_distance(p + eps * e, half) - box_distance(p - eps * e, half)) / (2 * eps)
         for e in np.eye(3)], axis=1,
    )  # fmt: skip
    ok = near & (exact > grid.cell)
    angle = np.arccos(np.clip(np.sum(n * g, axis=1) / np.linalg.norm(g, axis=1), -1.0, 1.0))
    assert np.max(angle[ok]) < 0.4


def test_outside_the_grid_a_lower_bound_at_least_the_band(box):
    """A point the grid does not cover is answered the band plus its distance from the grid's box,
    never more than the exact distance, with the box's outward normal."""
    half, _, grid = box
    rng = np.random.default_rng(3)
    directions = rng.normal(size=(500, 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    p = directions * rng.uniform(0.2, 2.0, (500, 1))
    shape = np.array(grid.values.shape)
    lo, hi = grid.origin, grid.origin + grid.cell * (shape - 1)
    out = np.any((p < lo) | (p > hi), axis=1)
    assert out.sum() > 400
    d, n = grid.at(p[out])
    assert np.all(d >= grid.band)
    assert np.all(d <= box_distance(p[out], half) + 1e-12)
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
    assert np.all(np.sum(n * p[out], axis=1) > 0.0)  # away from the box


def test_an_open_plate_is_unsigned_on_both_sides():
    """An open mesh (a square plate of two triangles) is two-sided: above and below its middle the
    grid is ``|z|`` exactly, the normal pointing away on each side."""
    s = 0.1
    plate = Mesh(
        (np.array([[-s, -s, 0], [s, -s, 0], [s, s, 0], [-s, s, 0]]), [[0, 1, 2], [0, 2, 3]])
    )
    grid = dg.grid_for(plate.mesh, TAU)
    z = np.linspace(0.002, 0.012, 11)
    p = np.c_[np.full(22, 0.013), np.full(22, -0.021), np.r_[z, -z]]
    d, n = grid.at(p)
    assert np.max(np.abs(d - np.abs(p[:, 2]))) < 1e-15
    assert np.allclose(n[:11], (0, 0, 1)) and np.allclose(n[11:], (0, 0, -1))


def test_its_sizes_hold_their_limits_and_a_grid_is_baked_once():
    """Cells of half the thickness where they fit; a long mesh's cells grow until at most
    ``MAX_NODES_ALONG`` nodes lie along it and ``MAX_NODES`` in all, the band at least three
    thicknesses and two cells; the same mesh and thickness give the same grid, baked once."""
    small = Mesh(box_triangles((0.05, 0.04, 0.02)))
    assert dg.cell_for(small.mesh, TAU) == (0.5 * TAU, dg.BAND_THICKNESS * TAU)
    long = Mesh(box_triangles((1.0, 0.6, 0.5)))
    cell, band = dg.cell_for(long.mesh, 0.001)
    dims = np.ceil((np.array([2.0, 1.2, 1.0]) + 2 * band) / cell) + 1
    assert dims.max() <= dg.MAX_NODES_ALONG and np.prod(dims) <= dg.MAX_NODES
    assert band >= max(dg.BAND_THICKNESS * 0.001, dg.BAND_CELLS * cell)
    assert dg.grid_for(small.mesh, TAU) is dg.grid_for(small.mesh, TAU)
    assert dg.grid_for(small.mesh, 2 * TAU).cell == TAU


def test_packed_grids_are_read_as_the_device_reads_them(box):
    """Two grids packed: each grid's box, its nodes and first value, and its values with z fastest,
    so that value ``start + (i·ny + j)·nz + k`` is node ``(i, j, k)``."""
    _, _, grid = box
    other = dg.grid_for(Mesh(box_triangles((0.02, 0.02, 0.02))).mesh, TAU)
    gbox, gdim, gval = dg.pack_grids([grid, other], np.float64)
    for m, g in enumerate((grid, other)):
        nx, ny, nz, start = gdim[m]
        assert (nx, ny, nz) == g.values.shape
        assert np.array_equal(gbox[m], [*g.origin, g.cell, g.band])
        i, j, k = nx - 2, ny // 2, 1
        assert gval[start + (i * ny + j) * nz + k] == g.values[i, j, k]
    assert len(gval) == grid.values.size + other.values.size
    assert math.isclose(dg.pack_grids([], np.float32)[2][0], 0.0)
