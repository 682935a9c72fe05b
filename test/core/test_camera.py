"""The depth camera against closed forms: a plane's distance and a square's pinhole silhouette, the
ray–sphere intersection, the nearest surface winning, back-projection onto the labelled triangle,
points() = depth·K⁻¹(u, v, 1), the Kinect noise's spread and seed, and bad settings refused."""

import math

import numpy as np
import pytest

from cloth_sim import ClothModel, Simulator
from cloth_sim import colliders as col
from cloth_sim.sensors.camera import DepthCamera, kinect_sigma

DOWN = (0.0, 1.0, 0.0, 0.0)  # the optical frame looking along world −z


def square(side=0.4, z=0.0, centre=(0.0, 0.0)):
    """A flat square cloth of two triangles at height z."""
    h = side / 2
    x0, y0 = centre
    v = np.array(
        [[x0 - h, y0 - h, z], [x0 + h, y0 - h, z], [x0 + h, y0 + h, z], [x0 - h, y0 + h, z]]
    )
    model = ClothModel.from_springs(
        v,
        np.full(4, 0.01),
        [[0, 1], [1, 2], [2, 3], [3, 0]],
        10.0,
        triangles=[[0, 1, 2], [0, 2, 3]],
        pinned=[0, 1, 2, 3],
    )
    return model


def sim_with(model=None, colliders=()):
    model = model if model is not None else square(z=-50.0, side=0.01)  # a cloth far out of view
    return Simulator(model, colliders=list(colliders), gravity=(0, 0, 0))


def test_a_plane_facing_the_camera_reads_its_distance_everywhere():
    cam = DepthCamera(
        width=64,
        height=48,
        fx=50,
        fy=50,
        cx=31.5,
        cy=23.5,
        position=(0.3, -0.2, 2.0),
        orientation=DOWN,
    )
    f = cam.render(sim_with(colliders=[col.Plane(normal=(0, 0, 1), offset=0.25)]))
    assert np.all(f.object == 1) and np.all(f.triangle == -1)
    np.testing.assert_allclose(f.depth, 1.75, rtol=0, atol=1e-6)


def test_a_square_cloth_covers_exactly_its_pinhole_projection():
    # looking down from 2 m at a 0.4 m square at z = 0: columns u with |(u − cx)/fx · 2| < 0.2
    cam = DepthCamera(
        width=80,
        height=60,
        fx=100,
        fy=100,
        cx=39.3,
        cy=29.6,
        position=(0, 0, 2.0),
        orientation=DOWN,
    )
    f = cam.render(sim_with(square()))
    u = (np.arange(80) - 39.3) / 100 * 2.0
    v = (np.arange(60) - 29.6) / 100 * 2.0
    inside = (np.abs(v)[:, None] < 0.2) & (np.abs(u)[None, :] < 0.2)
    np.testing.assert_array_equal(f.object == 0, inside)
    np.testing.assert_allclose(f.depth[inside], 2.0, atol=1e-6)
    assert np.all(np.isnan(f.depth[~inside]))
    assert set(np.unique(f.triangle[inside])) == {0, 1}


def test_identity_orientation_looks_along_plus_z_with_image_x_along_plus_x():
    cam = DepthCamera(
        width=41,
        height=41,
        fx=40,
        fy=40,
        cx=20,
        cy=20,
        position=(0, 0, 0),
        orientation=(1, 0, 0, 0),
    )
    f = cam.render(sim_with(colliders=[col.Sphere(center=(0.5, 0.25, 3.0), radius=0.1)]))
    rows, cols = np.nonzero(f.object == 1)
    # the sphere's centre projects to u = 40·0.5/3 + 20, v = 40·0.25/3 + 20
    assert cols.mean() == pytest.approx(40 * 0.5 / 3 + 20, abs=0.5)
    assert rows.mean() == pytest.approx(40 * 0.25 / 3 + 20, abs=0.5)


def test_a_sphere_reads_the_ray_sphere_intersection():
    c, r = np.array([0.1, -0.05, 0.0]), 0.3
    cam = DepthCamera(
        width=60, height=50, fx=60, fy=55, cx=29.5, cy=24.5, position=(0, 0, 1.5), orientation=DOWN
    )
    f = cam.render(sim_with(colliders=[col.Sphere(center=c, radius=r)]))
    # independently: rays in the world, d = R·(x, y, 1); |o + t d − c|² = r², depth = t
    R = cam.rotation
    uu, vv = np.meshgrid((np.arange(60) - 29.5) / 60, (np.arange(50) - 24.5) / 55)
    d = np.stack([uu, vv, np.ones_like(uu)], axis=-1) @ R.T
    oc = cam.position - c
    a = (d * d).sum(-1)
    b = 2 * (d * oc).sum(-1)
    disc = b * b - 4 * a * ((oc * oc).sum() - r * r)
    hit = disc >= 0
    t = np.where(hit, (-b - np.sqrt(np.where(hit, disc, 0))) / (2 * a), np.nan)
    np.testing.assert_array_equal(f.object == 1, hit)
    np.testing.assert_allclose(f.depth[hit], t[hit], rtol=1e-6)


def test_boxes_and_capsules_read_their_surfaces():
    cam = DepthCamera(
        width=21, height=21, fx=20, fy=20, cx=10, cy=10, position=(0, 0, 2.0), orientation=DOWN
    )
    f = cam.render(sim_with(colliders=[col.Box(center=(0, 0, 0.5), half_extents=(0.3, 0.3, 0.1))]))
    assert f.depth[10, 10] == pytest.approx(2.0 - 0.6, abs=1e-6)  # its top face
    f = cam.render(
        sim_with(colliders=[col.Capsule(a=(-0.5, 0, 0.2), b=(0.5, 0, 0.2), radius=0.1)])
    )
    assert f.depth[10, 10] == pytest.approx(2.0 - 0.3, abs=1e-6)  # the top of its cylinder
    # its end cap: pixel column 10 + 6 looks along x = 0.3·z (optical x is world x here), past the
    # cylinder's end, and meets the sphere of radius 0.1 around b = (0.5, 0, 0.2):
    # (0.3 z − 0.5)² + (1.8 − z)² = 0.1²
    A, B, C = 0.3**2 + 1, -2 * (0.3 * 0.5 + 1.8), 0.5**2 + 1.8**2 - 0.01
    disc = B * B - 4 * A * C
    assert disc > 0
    assert f.depth[10, 16] == pytest.approx((-B - math.sqrt(disc)) / (2 * A), abs=1e-6)


def test_the_nearest_surface_wins():
    cam = DepthCamera(
        width=32, height=32, fx=30, fy=30, cx=15.0, cy=15.0, position=(0, 0, 2.0), orientation=DOWN
    )
    sim = sim_with(
        square(side=2.0, z=0.5),
        colliders=[col.Plane(offset=0.0), col.Sphere(center=(0, 0, 1.0), radius=0.2)],
    )
    f = cam.render(sim)
    assert f.object[15, 15] == 2 and f.depth[15, 15] == pytest.approx(0.8, abs=1e-6)  # the sphere
    assert f.object[0, 0] == 0 and f.depth[0, 0] == pytest.approx(
        1.5, abs=1e-6
    )  # cloth over plane
    assert np.all(f.object >= 0)


def test_back_projected_points_lie_on_the_triangle_each_pixel_names():
    model = ClothModel.grid(
        12, 12, 0.05, 0.01, stiffness=200.0, damping=0.5, pinned=[(0, 0), (0, -1)]
    )
    sim = Simulator(model)
    sim.advance(0.3)  # a curved, swinging cloth
    cam = DepthCamera(
        width=120,
        height=90,
        fx=110,
        fy=110,
        cx=59.5,
        cy=44.5,
        position=(0.27, -0.6, 0.4),
        orientation=(0.39, -0.92, 0.0, 0.0),
    )
    f = cam.render(sim)
    rows, cols = np.nonzero(f.triangle >= 0)
    assert len(rows) > 500
    p = f.points()[rows, cols].astype(np.float64) @ cam.rotation.T + cam.position
    t = model.triangles[f.triangle[rows, cols]]
    a, b, c = (sim.positions[t[:, k]] for k in range(3))
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1)[:, None]
    assert np.abs(((p - a) * n).sum(1)).max() < 1e-5  # float32 depth
    # and the point's place at rest lies on the rest triangle (flat: z = 0)
    rest = f.rest_points(sim.positions, model.positions, model.triangles)[rows, cols]
    assert np.abs(rest[:, 2]).max() < 1e-5
    assert rest[:, 0].min() >= -1e-5 and rest[:, 0].max() <= 0.55 + 1e-5


def test_points_are_depth_times_the_inverse_intrinsics():
    cam = DepthCamera(
        width=40, height=30, fx=33, fy=37, cx=18.2, cy=16.9, position=(0, 0, 2.0), orientation=DOWN
    )
    f = cam.render(sim_with(colliders=[col.Sphere(center=(0, 0, 0), radius=1.0)]))
    pts = f.points()
    K_inv = np.linalg.inv(cam.K)
    for v, u in [(0, 0), (15, 20), (29, 39), (7, 3)]:
        want = f.depth[v, u] * (K_inv @ [u, v, 1.0])
        if np.isnan(f.depth[v, u]):
            assert np.all(np.isnan(pts[v, u]))
        else:
            np.testing.assert_allclose(pts[v, u], want, rtol=1e-6)
    # into a caller's buffer (what the node reuses every frame): the same numbers; a wrong one
    # refused
    buf = np.zeros((30, 40, 3), np.float32)
    assert f.points(out=buf) is buf
    np.testing.assert_array_equal(buf, pts)
    with pytest.raises(ValueError, match="out must be a C-contiguous float32 array of shape"):
        f.points(out=np.zeros((30, 40, 3)))


def test_kinect_noise_has_its_spread_and_a_seed_reproduces_an_image():
    plane = [col.Plane(offset=0.0)]
    kw = dict(
        width=320,
        height=240,
        fx=300,
        fy=300,
        cx=159.5,
        cy=119.5,
        position=(0, 0, 1.5),
        orientation=DOWN,
    )
    f = DepthCamera(noise="kinect", seed=7, **kw).render(sim_with(colliders=plane))
    err = f.depth.astype(np.float64) - 1.5
    assert np.std(err) == pytest.approx(kinect_sigma(1.5), rel=0.05)
    assert abs(np.mean(err)) < 3 * kinect_sigma(1.5) / math.sqrt(err.size) * 3
    again = DepthCamera(noise="kinect", seed=7, **kw).render(sim_with(colliders=plane))
    np.testing.assert_array_equal(f.depth, again.depth)
    other = DepthCamera(noise="kinect", seed=8, **kw).render(sim_with(colliders=plane))
    assert not np.array_equal(f.depth, other.depth)


@pytest.mark.parametrize(
    "kw, words",
    [
        ({"width": 0}, "width must be an integer in [1, 8192]"),
        ({"height": 1.5}, "height must be an integer"),
        ({"fx": 0.0}, "fx must be a finite focal length > 0"),
        ({"cy": math.nan}, "cy must be a finite principal point"),
        ({"near": 0.0}, "near must be a finite distance > 0"),
        ({"near": 2.0, "far": 1.0}, "far must be a finite distance > near"),
        ({"orientation": (0, 0, 0, 0)}, "orientation"),
        ({"position": (0, math.inf, 0)}, "position"),
        ({"noise": "gaussian"}, "noise must be one of None, 'kinect'"),
    ],
)
def test_bad_settings_are_refused_naming_the_field(kw, words):
    with pytest.raises(ValueError) as e:
        DepthCamera(**kw)
    assert words in str(e.value)
