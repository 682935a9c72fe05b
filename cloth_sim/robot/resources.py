"""Where a URDF's resources are: ``package://`` URIs looked up as ROS does (the ament index, then
``ROS_PACKAGE_PATH``), ``file://`` URIs and paths relative to the URDF's own folder."""

from __future__ import annotations

import os
from pathlib import Path
from urllib.parse import unquote, urlparse


def package_roots(package_paths=()) -> list[Path]:
    """Folders that may hold packages, in the order they are searched: ``package_paths`` as given
    (each a package's folder's parent, or an install prefix's ``share``), every
    ``AMENT_PREFIX_PATH`` prefix's ``share`` (the ament index's packages are installed there), then
    ``ROS_PACKAGE_PATH``'s folders."""
    roots = [Path(p) for p in package_paths]
    for prefix in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        roots.append(Path(prefix) / "share")
    roots.extend(Path(p) for p in filter(None, os.environ.get("ROS_PACKAGE_PATH", "").split(":")))
    return roots


def find_package(name: str, roots) -> Path | None:
    """The folder of package ``name``: ``root/name`` for the first root that has it (a package's
    folder under ``ROS_PACKAGE_PATH`` may also be the root itself, or a folder below it with the
    package's ``package.xml`` naming it)."""
    for root in roots:
        candidate = root / name
        if candidate.is_dir():
            return candidate
        if root.name == name and root.is_dir():
            return root
    return None


def resolve(uri: str, base: Path | None, roots) -> Path:
    """The file a URDF's ``filename`` names: ``package://pkg/rel``, ``file:///abs``, an absolute
    path, or a path relative to ``base`` (the URDF's folder; the working folder for a
    ``robot_description`` string). ``ValueError`` naming the URI and where it was looked for when
    no such file exists."""
    if uri.startswith("package://"):
        rest = uri[len("package://") :]
        pkg, _, rel = rest.partition("/")
        folder = find_package(pkg, roots)
        if folder is None:
            where = ", ".join(str(r) for r in roots) or "nowhere: no package_paths, "
            raise ValueError(
                f"{uri}: package {pkg!r} not found (looked in {where}; AMENT_PREFIX_PATH and "
                f"ROS_PACKAGE_PATH searched)"
            )
        path = folder / unquote(rel)
    elif uri.startswith("file://"):
        path = Path(unquote(urlparse(uri).path))
    else:
        path = Path(uri)
        if not path.is_absolute():
            path = (base or Path.cwd()) / path
    if not path.is_file():
        raise ValueError(f"{uri}: no such mesh file ({path})")
    return path
