"""numba's on-disk cache kept true to the source across files.

numba keys a cached kernel by its own file: it compiles the kernel again when that file changes,
but not when a function it inlines or calls, or a constant it reads, comes from another file that
changed. Such a kernel keeps running the old code (2026-12-02: ``vbd_kernels.iterate_parallel``,
cached while ``vbd_contact.py`` held an experiment and kept after the file was restored, moved
robot_sweep's state after 300 steps, which looked for a day like a cache-order dependence).

Each module that caches kernels ends with ``keep_true(__name__)``. It records, beside the module's
cache (``<module>.sources.json`` in the kernels' cache directory, wherever numba keeps it: the
package's ``__pycache__``, ``NUMBA_CACHE_DIR`` or the user's cache), the SHA-256 of every file of
the package that the module imports, directly or through others. When one of them differs on a
later import, it empties the module's cached kernels before any of them is loaded, so they compile
from the source as it is. The test is a superset: a file reached only through a non-kernel import
(``physics/mesh.py`` from ``force_kernels``, through ``bending``) also empties it, which costs a
compile, never a wrong result. The digests take ~5 ms a process (each file is read once).
``test_kernel_cache.py`` checks that every module with cached kernels calls it.
"""

from __future__ import annotations

import ast
import hashlib
import json
import os
import sys
from pathlib import Path

from numba.core.caching import FunctionCache
from numba.core.dispatcher import Dispatcher

__all__ = ["keep_true", "module_sources"]

#: each file's SHA-256 in this process (a file is read once however many modules reach it)
_digests: dict[Path, str] = {}


def keep_true(module_name: str) -> bool:
    """Empty the cached kernels of the module ``module_name`` (imported, or at the end of its
    own import) if a file of its package that it imports has changed since they were cached;
    returns whether it did. A cache directory that cannot be written is left as it is (numba
    does not cache there either)."""
    module = sys.modules[module_name]
    kernels = [
        value
        for value in vars(module).values()
        if isinstance(value, Dispatcher)
        and value.py_func.__module__ == module_name
        and value.stats.cache_path
    ]
    if not kernels:
        return False
    record = Path(kernels[0].stats.cache_path) / f"{module_name}.sources.json"
    package = module_name.partition(".")[0]
    root = Path(sys.modules[package].__file__).parent
    try:
        kept = json.loads(record.read_text())["sources"]
        if all(_digest(root / name) == digest for name, digest in kept.items()):
            return False
    except (OSError, ValueError, KeyError, TypeError):
        pass  # no record yet, or not one of ours: empty the cache and write one
    sources = {
        path.relative_to(root).as_posix(): _digest(path)
        for path in module_sources(module_name, root)
    }
    try:
        for kernel in kernels:
            FunctionCache(kernel.py_func).flush()
        partial = record.with_name(f"{record.name}.{os.getpid()}")
        partial.write_text(json.dumps({"module": module_name, "sources": sources}, indent=1))
        os.replace(partial, record)
    except OSError:
        return False
    return True


def module_sources(module_name: str, root: Path) -> list[Path]:
    """The files of the package at ``root`` (named ``module_name``'s first part) that the module
    imports, directly or through others, its own first. ``from p import n`` reaches ``p.n`` where
    that is a module, else ``p`` and, for a package, each module in it (its ``__init__`` may hand
    out its modules' names lazily)."""
    package = module_name.partition(".")[0]
    first = _module_file(module_name, package, root)
    if first is None:
        raise ValueError(f"module_name: no module {module_name!r} under {root}")
    files = {module_name: first}
    todo = [module_name]
    while todo:
        name = todo.pop()
        for reached in sorted(_imported(name, files[name], package, root)):
            path = _module_file(reached, package, root)
            if path is not None and reached not in files and path not in files.values():
                files[reached] = path
                todo.append(reached)
    return list(files.values())


def _imported(name: str, path: Path, package: str, root: Path) -> set[str]:
    """The modules of ``package`` (rooted at ``root``) that the module ``name``, its file
    ``path``, imports."""
    here = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_bytes(), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            origin = node.module or ""
            if node.level:
                parts = here.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1])
                origin = f"{base}.{node.module}" if node.module else base
            names = [f"{origin}.{alias.name}" for alias in node.names]
            modules = [n for n in names if _module_file(n, package, root) is not None]
            found.update(modules)
            if len(modules) < len(names):  # names of the module, or of the package's __init__
                found.add(origin)
                origin_path = _module_file(origin, package, root)
                if origin_path is not None and origin_path.name == "__init__.py":
                    found.update(
                        f"{origin}.{child.stem if child.suffix else child.name}"
                        for child in origin_path.parent.iterdir()
                        if child.suffix == ".py" or (child / "__init__.py").is_file()
                    )
    return {module for module in found if module.partition(".")[0] == package}


def _module_file(name: str, package: str, root: Path) -> Path | None:
    """The file of the module ``name`` of ``package`` (rooted at ``root``), or None."""
    parts = name.split(".")
    if parts[0] != package:
        return None
    base = root.joinpath(*parts[1:])
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.is_file():
            return path
    return None


def _digest(path: Path) -> str:
    """``path``'s SHA-256 (hex), read once a process; "" for a file that is gone."""
    if path not in _digests:
        try:
            _digests[path] = hashlib.sha256(path.read_bytes()).hexdigest()
        except OSError:
            _digests[path] = ""
    return _digests[path]
