"""Generate and build the package's own interfaces (msg/, srv/), and the standard ones no wheel has
(interfaces/: simulation_interfaces, tf2_msgs), with rosidl from the PyPI wheels.

Run by `make` with the project's venv Python. It applies the fix the wheels need (their exported
CMake files name the wheel build host's Python and numpy include directories), configures this
package's CMakeLists.txt with CLOTH_SIM_INTERFACES_ONLY=ON, builds, and installs into
build/interfaces/install (its libraries linked into the venv's lib/); a .pth file then puts the
generated Python package behind the hand-written one, which extends its __path__ to it (see
cloth_sim/__init__.py). The ament index entries and share/cloth_sim are linked into the venv, so
the venv is an ament prefix of cloth_sim (`ros2 interface show`, `ros2 run`, `ros2 launch` find
it). On a real ROS 2 install none of this is used: `colcon build` builds the same CMakeLists.txt.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy

ROOT = Path(__file__).resolve().parent.parent
BUILD = ROOT / "build" / "interfaces"
PREFIX = BUILD / "install"
HOST_PY_INCLUDE = "/opt/python/cp311-cp311/include/python3.11"
HOST_NUMPY_INCLUDE = "/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include"
#: included into each package's configure: rosidl_generate_interfaces without the C++ generators
PYTHON_ONLY = ROOT / "tools" / "python_only_interfaces.cmake"
#: standard interface packages no wheel has, generated from interfaces/<name> (see its README)
VENDORED = ("simulation_interfaces", "tf2_msgs")


def fix_wheel_cmake_paths(venv: Path) -> int:
    """Point the wheels' exported CMake files at this venv's Python and numpy headers."""
    ours = {
        HOST_PY_INCLUDE: sysconfig.get_paths()["include"],
        HOST_NUMPY_INCLUDE: numpy.get_include(),
    }
    changed = 0
    for path in (venv / "share").rglob("*.cmake"):
        text = path.read_text()
        if "/opt/python/" not in text:
            continue
        for old, new in ours.items():
            text = text.replace(old, new)
        path.write_text(text)
        changed += 1
    return changed


def _link(link: Path, target: Path) -> None:
    link.parent.mkdir(parents=True, exist_ok=True)
    if link.is_symlink() or link.is_file():
        link.unlink()
    elif link.exists():
        shutil.rmtree(link)
    link.symlink_to(target)


def expose_in_venv(venv: Path) -> None:
    """Make the venv an ament prefix of cloth_sim, as a colcon install is: its ament index entries
    and ``share/cloth_sim`` (the generated interfaces, package.xml, and the repository's config/
    and launch/) linked under ``venv/share``, and ``lib/cloth_sim/cloth_sim_node``. With
    ``AMENT_PREFIX_PATH`` holding the venv, ``ros2 interface show cloth_sim/msg/Stats``,
    ``ros2 run cloth_sim cloth_sim_node`` and ``ros2 launch cloth_sim cloth_sim.launch.py``
    work."""
    index = PREFIX / "share" / "ament_index" / "resource_index"
    for name in ("cloth_sim", *VENDORED):
        for entry in index.glob(f"*/{name}"):
            _link(
                venv / "share" / "ament_index" / "resource_index" / entry.parent.name / name, entry
            )
    for name in VENDORED:
        _link(venv / "share" / name, PREFIX / "share" / name)
    share = PREFIX / "share" / "cloth_sim"
    # real directories of linked files: `ros2 launch` looks for launch files with os.walk, which
    # does not enter linked directories
    for name in ("config", "launch"):
        if (share / name).is_symlink():  # an older layout linked the directories themselves
            (share / name).unlink()
        for path in (ROOT / name).rglob("*"):
            if path.is_file():
                _link(share / path.relative_to(ROOT), path)
    _link(venv / "share" / "cloth_sim", share)
    _link(venv / "lib" / "cloth_sim" / "cloth_sim_node", venv / "bin" / "cloth_sim_node")


def main() -> int:
    venv = Path(sys.prefix)
    fixed = fix_wheel_cmake_paths(venv)
    if fixed:
        print(f"build_interfaces: pointed {fixed} wheel CMake files at this venv's include dirs")
    cmake = shutil.which("cmake")
    if cmake is None:
        print(
            "build_interfaces: error: cmake (>= 3.8) is needed to generate msg/", file=sys.stderr
        )
        return 1
    env = dict(os.environ)
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    env["VIRTUAL_ENV"] = str(venv)
    rpath = f"{PREFIX / 'lib'};{venv / 'lib'}"
    if PREFIX.exists():
        shutil.rmtree(PREFIX)
    env["CMAKE_PREFIX_PATH"] = f"{PREFIX}{os.pathsep}{venv}"
    env["AMENT_PREFIX_PATH"] = f"{PREFIX}{os.pathsep}{venv}"
    # the standard interfaces no wheel has (interfaces/README.md), then the package's own
    packages = [
        (
            name,
            ROOT / "interfaces" / name,
            ["CMakeLists.txt", "package.xml"],
            [d for d in ("msg", "srv", "action") if (ROOT / "interfaces" / name / d).is_dir()],
            [],
        )
        for name in VENDORED
    ]
    packages.append(
        (
            "cloth_sim",
            ROOT,
            ["CMakeLists.txt", "package.xml"],
            ["msg", "srv"],
            ["-DCLOTH_SIM_INTERFACES_ONLY=ON"],
        )
    )
    for name, root, files, dirs, options in packages:
        # CMake refuses exported include dirs inside the source tree, and the venv (with numpy's
        # headers) lives in the repository: configure from a copy of what the interfaces need.
        src = BUILD / "src" / name
        if src.exists():
            shutil.rmtree(src)
        src.mkdir(parents=True)
        for f in files:
            shutil.copy2(root / f, src / f)
        for d in dirs:
            shutil.copytree(root / d, src / d)
        work = BUILD / "cmake" / name
        work.mkdir(parents=True, exist_ok=True)
        configure = [
            cmake,
            "-S",
            str(src),
            "-B",
            str(work),
            *options,
            "-DBUILD_TESTING=OFF",
            f"-DPython3_EXECUTABLE={venv / 'bin' / 'python3'}",
            f"-DCMAKE_INSTALL_PREFIX={PREFIX}",
            f"-DCMAKE_INSTALL_RPATH={rpath}",
            "-DCMAKE_BUILD_TYPE=Release",
            # Python loads the C type supports only: the C++ generators are left out here (not
            # in a colcon build), which halves the build
            f"-DCMAKE_PROJECT_INCLUDE={PYTHON_ONLY}",
        ]
        for cmd in (
            configure,
            [cmake, "--build", str(work), "-j", str(os.cpu_count() or 2)],
            [cmake, "--install", str(work)],
        ):
            out = subprocess.run(
                cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
            )
            if out.returncode != 0:
                print(out.stdout[-6000:], file=sys.stderr)
                print(
                    f"build_interfaces: error: {name}: {' '.join(cmd[:3])} … failed "
                    f"({out.returncode})",
                    file=sys.stderr,
                )
                return 1
        print(f"build_interfaces: {name} built", flush=True)
    # rosidl's type-support dispatch dlopens the libraries by name along LD_LIBRARY_PATH, which the
    # wheels' bootstrapper sets to the venv's lib/: link them there.
    for name in ("cloth_sim", *VENDORED):
        for lib in (PREFIX / "lib").glob(f"lib{name}__*.so"):
            link = venv / "lib" / lib.name
            if link.is_symlink() or link.exists():
                link.unlink()
            link.symlink_to(lib)
    expose_in_venv(venv)
    site = next(PREFIX.glob("lib/python3*/site-packages"))
    pth = Path(sysconfig.get_paths()["purelib"]) / "cloth_sim_interfaces.pth"
    pth.write_text(f"{site}\n")
    print(f"build_interfaces: msg/, srv/ and {', '.join(VENDORED)} generated into {site}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
