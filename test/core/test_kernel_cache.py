"""numba's cache kept true to the source across files (cloth_sim.kernel_cache)."""

from __future__ import annotations

import ast
import dis
import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from numba.core.dispatcher import Dispatcher

import cloth_sim
from cloth_sim.integrators import vbd_kernels
from cloth_sim.kernel_cache import module_sources

ROOT = Path(cloth_sim.__file__).parent

CALLER = """
import numba
{guard_import}
from .helpers import called, inlined
from .shapes import SCALE

@numba.njit(cache=True)
def kernel(x):
    return inlined(x) + called(x) + SCALE
{guard}
"""
HELPERS = """
import numba

@numba.njit(inline="always")
def inlined(x):
    return {a} * x

@numba.njit
def called(x):
    return {b} * x
"""


def _package(tmp_path: Path, name: str, guarded: bool) -> None:
    package = tmp_path / name
    (package / "shapes").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "shapes" / "__init__.py").write_text("from .sizes import SCALE\n")
    (package / "shapes" / "sizes.py").write_text("SCALE = 100.0\n")
    (package / "helpers.py").write_text(HELPERS.format(a=1.0, b=10.0))
    (package / "caller.py").write_text(
        CALLER.format(
            guard_import="from cloth_sim.kernel_cache import keep_true" if guarded else "",
            guard="print('emptied', keep_true(__name__))" if guarded else "",
        )
    )


def _run(tmp_path: Path, name: str) -> list[str]:
    """A fresh process imports the caller and prints its kernel's answer at 1."""
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(tmp_path), str(ROOT.parent)]),
        "NUMBA_CACHE_DIR": str(tmp_path / "cache"),
    }
    out = subprocess.run(
        [sys.executable, "-c", f"from {name}.caller import kernel; print(kernel(1.0))"],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return out.stdout.split()


def test_numba_alone_keeps_another_files_old_code(tmp_path):
    """Why the module exists: without it, a cached kernel keeps the code it inlined and called
    from another file, and the constant it read there, after that file changes (numba 0.68).
    Should numba learn this, this test fails and kernel_cache can go."""
    _package(tmp_path, "unguarded", guarded=False)
    assert _run(tmp_path, "unguarded") == ["111.0"]
    (tmp_path / "unguarded" / "helpers.py").write_text(HELPERS.format(a=2.0, b=20.0))
    (tmp_path / "unguarded" / "shapes" / "sizes.py").write_text("SCALE = 300.0\n")
    assert _run(tmp_path, "unguarded") == ["111.0"]  # stale: 322 from the source


@pytest.mark.parametrize("edit", ["helpers", "constant"])
def test_a_kernel_compiles_again_when_a_file_it_imports_changes(tmp_path, edit):
    _package(tmp_path, "guarded", guarded=True)
    assert _run(tmp_path, "guarded") == ["emptied", "True", "111.0"]  # no record yet
    assert _run(tmp_path, "guarded") == ["emptied", "False", "111.0"]  # from the cache
    if edit == "helpers":
        (tmp_path / "guarded" / "helpers.py").write_text(HELPERS.format(a=2.0, b=20.0))
        expected = "122.0"
    else:  # a constant, through a package's __init__
        (tmp_path / "guarded" / "shapes" / "sizes.py").write_text("SCALE = 300.0\n")
        expected = "311.0"
    assert _run(tmp_path, "guarded") == ["emptied", "True", expected]
    assert _run(tmp_path, "guarded") == ["emptied", "False", expected]


def test_a_modules_sources_are_what_it_imports_through_any_path(tmp_path):
    _package(tmp_path, "guarded", guarded=True)
    names = {
        p.relative_to(tmp_path / "guarded").as_posix()
        for p in module_sources("guarded.caller", tmp_path / "guarded")
    }
    assert names == {"caller.py", "helpers.py", "shapes/__init__.py", "shapes/sizes.py"}
    vbd = {
        p.relative_to(ROOT).as_posix()
        for p in module_sources("cloth_sim.integrators.vbd_kernels", ROOT)
    }
    assert {"integrators/vbd_contact.py", "contact/collider_kernels.py", "kinds.py"} <= vbd
    assert not any(name.startswith(("ros/", "bench/")) for name in vbd)
    with pytest.raises(ValueError, match="module_name"):
        module_sources("cloth_sim.no_such_module", ROOT)


def _cached_kernels(tree: ast.Module) -> list[ast.FunctionDef]:
    """The functions decorated ``…(cache=True, …)`` anywhere in ``tree``."""
    return [
        node
        for node in ast.walk(tree)
        if isinstance(node, ast.FunctionDef)
        and any(
            isinstance(d, ast.Call)
            and any(
                k.arg == "cache" and getattr(k.value, "value", None) is True for k in d.keywords
            )
            for d in node.decorator_list
        )
    ]


def test_every_module_that_caches_kernels_keeps_them_true():
    """A module that caches kernels ends with ``keep_true(__name__)``, and its cached kernels are
    module-level functions (the ones keep_true finds)."""
    modules = 0
    for path in sorted(ROOT.rglob("*.py")):
        tree = ast.parse(path.read_bytes())
        kernels = _cached_kernels(tree)
        if not kernels:
            continue
        modules += 1
        where = path.relative_to(ROOT)
        assert all(k in tree.body for k in kernels), (
            f"{where}: a cached kernel not at module level"
        )
        calls = [
            node
            for node in tree.body
            if isinstance(node, ast.Expr)
            and isinstance(node.value, ast.Call)
            and getattr(node.value.func, "id", None) == "keep_true"
        ]
        assert calls and ast.unparse(calls[-1].value.args[0]) == "__name__", (
            f"{where} caches kernels but does not call keep_true(__name__)"
        )
        assert tree.body.index(calls[-1]) > max(tree.body.index(k) for k in kernels), where
    assert modules >= 20


def test_the_record_sits_beside_the_kernels_cache():
    name = "cloth_sim.integrators.vbd_kernels"
    record = Path(vbd_kernels.sweep.stats.cache_path) / f"{name}.sources.json"
    kept = json.loads(record.read_text())
    assert kept["module"] == name
    assert {p.relative_to(ROOT).as_posix() for p in module_sources(name, ROOT)} == set(
        kept["sources"]
    )


def _kernel_modules() -> list[str]:
    """The package's modules that cache kernels (``cloth_sim.cuda`` aside: its kernels are
    numba-cuda's)."""
    names = []
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT.parent).with_suffix("")
        if rel.parts[1] != "cuda" and _cached_kernels(ast.parse(path.read_bytes())):
            names.append(".".join(rel.parts))
    return names


def _callees(kernel: Dispatcher) -> list[Dispatcher]:
    """The jitted functions ``kernel``'s code names as globals."""
    f = kernel.py_func
    named = {i.argval for i in dis.get_instructions(f) if i.opname == "LOAD_GLOBAL"}
    return [
        f.__globals__[n] for n in sorted(named) if isinstance(f.__globals__.get(n), Dispatcher)
    ]


def test_a_callee_of_a_fastmath_kernel_says_its_own_fastmath():
    """numba compiles a jitted function that sets no ``fastmath`` with its first caller's (a flag
    it inherits), and caches that build for every later caller: a function that a kernel with
    ``fastmath`` calls, compiled on its own, would contract its arithmetic or not by which kernel
    compiled it first (robot_sweep and drape on ``vbd`` ended on other bits after ``make
    install``'s compilation than in a process compiling lazily, 2026-12-03). Every such callee,
    reached through inlined helpers too, says its own."""
    kernels = {}
    for name in _kernel_modules():
        module = importlib.import_module(name)
        kernels.update(
            {(name, k): v for k, v in vars(module).items() if isinstance(v, Dispatcher)}
        )
    roots = [k for k in kernels.values() if k.targetoptions.get("fastmath")]
    assert roots, "no kernel with fastmath: the check has nothing to walk"
    reached, todo = {}, list(roots)
    while todo:
        for callee in _callees(todo.pop()):
            key = (callee.py_func.__module__, callee.py_func.__qualname__)
            if key not in reached:
                reached[key] = callee
                todo.append(callee)
    compiled_alone = {
        key: d for key, d in reached.items() if d.targetoptions.get("inline", "never") == "never"
    }
    assert ("cloth_sim.integrators.vbd_contact", "asked") in compiled_alone
    unsaid = sorted(
        ".".join(k) for k, d in compiled_alone.items() if "fastmath" not in d.targetoptions
    )
    assert unsaid == [], "callees of a fastmath kernel that leave fastmath to their caller"
