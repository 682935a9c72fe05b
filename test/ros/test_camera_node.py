"""The node's side of the depth camera: what test_camera.py checks in the core, here through the
running node."""

import numpy as np
import pytest

DOWN = (0.0, 1.0, 0.0, 0.0)  # the optical frame looking along world −z


# --------------------------------------------------------------------------- the node's camera


def test_the_node_publishes_an_image_its_camera_info_and_the_cloud_they_make(ros):
    from sensor_msgs.msg import CameraInfo, Image, PointCloud2
    from tf2_msgs.msg import TFMessage

    ros.start(
        scene="drape",
        rows=12,
        cols=12,
        spacing=1.0 / 11,
        **{
            "camera.enable": True,
            "camera.width": 64,
            "camera.height": 48,
            "camera.fov": 70.0,
            "camera.position": [0.5, -0.6, 1.2],
            "camera.look_at": [0.5, 0.5, 0.0],
            "camera.rate": 20.0,
        },
    )
    images = ros.collect(Image, "/cloth_sim/camera/depth/image")
    infos = ros.collect(CameraInfo, "/cloth_sim/camera/depth/camera_info")
    clouds = ros.collect(PointCloud2, "/cloth_sim/camera/points")
    labels = ros.collect(Image, "/cloth_sim/camera/labels")
    tf = ros.collect(TFMessage, "/tf")

    def same_stamp():
        stamps = [
            {(m.header.stamp.sec, m.header.stamp.nanosec) for m in box}
            for box in (images, infos, clouds)
        ]
        return stamps[0] & stamps[1] & stamps[2]

    assert ros.spin_until(lambda: labels and same_stamp(), 20)
    stamp = sorted(same_stamp())[-1]

    def pick(box):
        return next(m for m in box if (m.header.stamp.sec, m.header.stamp.nanosec) == stamp)  # noqa: E731

    img, info, cloud = pick(images), pick(infos), pick(clouds)
    assert img.encoding == "32FC1" and (img.height, img.width) == (48, 64) and img.step == 4 * 64
    assert (
        img.header.frame_id
        == info.header.frame_id
        == cloud.header.frame_id
        == "cloth/camera_optical"
    )
    depth = np.frombuffer(bytes(img.data), np.float32).reshape(48, 64)
    assert np.isfinite(depth).sum() > 100
    # back-project the published image with the published intrinsics, independently
    fx, cx, fy, cy = info.k[0], info.k[2], info.k[4], info.k[5]
    u, v = np.meshgrid(np.arange(64), np.arange(48))
    want = np.stack([(u - cx) / fx * depth, (v - cy) / fy * depth, depth], axis=-1)
    xyz = np.frombuffer(bytes(cloud.data), np.float32).reshape(48, 64, 3)
    assert (cloud.height, cloud.width) == (48, 64)
    np.testing.assert_allclose(xyz, want, rtol=1e-6, atol=1e-6)  # NaN where the image is NaN
    lab = np.frombuffer(bytes(labels[-1].data), np.int16).reshape(48, 64)
    assert labels[-1].encoding == "16SC1" and {0, 1, 2} <= set(np.unique(lab).tolist())
    assert ros.spin_until(
        lambda: any(t.child_frame_id == "cloth/camera_optical" for m in tf for t in m.transforms),
        10,
    )


@pytest.mark.parametrize(
    "change, words",
    [
        ({"camera.near": 20.0}, "camera.far"),
        (
            {"camera.look_at": [0.5, -1.0, 1.0]},
            "camera.look_at must be a point other than camera.position",
        ),
        ({"camera.noise": "gaussian"}, "camera.noise"),
        ({"camera.width": 0}, "camera.width"),
    ],
)
def test_bad_camera_settings_are_refused_naming_the_field(ros, change, words):
    node = ros.start(**{"camera.enable": True, "camera.width": 32, "camera.height": 24})
    (result,) = ros.set_params("/cloth_sim", change)
    assert not result.successful and words in result.reason, result.reason
    assert node.publishing.camera.camera.width == 32  # the running camera is untouched


def test_look_at_gives_the_contract_s_orientations():
    from cloth_sim.sensors.camera import look_at_orientation

    np.testing.assert_allclose(
        np.abs(look_at_orientation((0, 0, 2), (0, 0, 0))), [0, 1, 0, 0], atol=1e-12
    )
    np.testing.assert_allclose(look_at_orientation((0, 0, 0), (0, 0, 5)), [1, 0, 0, 0], atol=1e-12)
