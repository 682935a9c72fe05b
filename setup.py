"""ament_python package (colcon build / ros2 run) that also installs with pip (make)."""

from glob import glob

from setuptools import find_packages, setup

package_name = "cloth_sim"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config/scenes", glob("config/scenes/*.yaml")),
    ],
    install_requires=["setuptools"],
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
        ],
    },
)
