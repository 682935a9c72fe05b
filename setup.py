"""The pip installation used by `make` here (console scripts cloth-sim and cloth_sim_node in
.venv/bin).

On a real ROS 2 install the package is built by colcon from CMakeLists.txt (build type ament_cmake,
because it generates msg/Stats.msg); this file is not used there.
"""

from glob import glob

from setuptools import find_packages, setup

package_name = "cloth_sim"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    data_files=[
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", ["config/cloth_sim.yaml"]),
        ("share/" + package_name + "/config/scenes", glob("config/scenes/*.yaml")),
        ("share/" + package_name + "/config/meshes", glob("config/meshes/*.obj")),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
    ],
    install_requires=["setuptools"],
    # the versions are pinned in requirements.txt; `pip install .[envs]` names what the tasks need
    extras_require={
        "envs": [
            "gymnasium>=1.2,<2",
            "numpy",
            "scipy",
            "numba",
            "pyyaml",
            "trimesh",
            "cholespy",
            "qdldl",
        ]
    },
    zip_safe=False,
    maintainer="cloth_sim developers",
    maintainer_email="cloth-sim@example.org",
    description="Real-time mass-spring cloth simulation (Provot 1995, Choi & Ko 2002) for ROS 2",
    license="Apache-2.0",
    python_requires=">=3.10",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "cloth-sim = cloth_sim.cli:main",
            "cloth_sim_node = cloth_sim.ros:main",
        ],
    },
)
