"""A compiled kernel that calls a parallel one, loaded from numba's cache into a fresh process,
runs (:mod:`cloth_sim.threads`): RK4's fused step once crashed there (numba/numba#8578)."""

import importlib
import os
import pkgutil
import subprocess
import sys

import numba

import cloth_sim

STEP = """
from cloth_sim.scene import load_scene
load_scene("hanging").build_simulator(integrator="{method}", dt=1e-5).step(3)
print("stepped")
"""


def _run(method: str, cache: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, NUMBA_CACHE_DIR=cache)
    return subprocess.run(
        [sys.executable, "-c", STEP.format(method=method)],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )


def test_rk4_loaded_from_the_cache_into_a_fresh_process_steps(tmp_path):
    """The sequence that crashed every time before the pool was started: the gather compiled for
    symplectic Euler in one process, the fused Runge–Kutta step in a second, then a third loads
    both from the cache and takes RK4's first step (a segmentation fault, return code −11)."""
    cache = str(tmp_path / "numba_cache")
    for method in ("symplectic_euler", "rk4", "rk4"):
        run = _run(method, cache)
        assert run.returncode == 0, (method, run.returncode, run.stderr[-2000:])
        assert run.stdout.strip().endswith("stepped")


def _serial_callers_of_parallel_kernels() -> set:
    """``(caller, callee)`` for every cached kernel compiled without ``parallel=True`` that calls
    one compiled with it by name, over the core's modules."""
    edges = set()
    for info in pkgutil.walk_packages(cloth_sim.__path__, "cloth_sim."):
        if info.name.split(".")[1] in ("ros", "cuda", "bench", "envs", "dataset", "sweep", "bag"):
            continue
        module = importlib.import_module(info.name)
        for name, value in vars(module).items():
            if not isinstance(value, numba.core.registry.CPUDispatcher):
                continue
            if value.targetoptions.get("parallel") or value.py_func.__module__ != info.name:
                continue
            scope = value.py_func.__globals__
            for called in value.py_func.__code__.co_names:
                other = scope.get(called)
                if isinstance(other, numba.core.registry.CPUDispatcher) and (
                    other.targetoptions.get("parallel")
                ):
                    edges.add((f"{info.name}.{name}", f"{other.py_func.__module__}.{called}"))
    return edges


def test_every_serial_kernel_calling_a_parallel_one_is_one_whose_builder_starts_the_pool():
    """The three such kernels are built by objects that call ``threads.start_pool`` (Forces with
    the fused gather, the strain limit's projection, Baraff–Witkin's CG): a new one must be too,
    and then be listed here."""
    assert _serial_callers_of_parallel_kernels() == {
        (
            "cloth_sim.physics.force_kernels.runge_kutta_fused",
            "cloth_sim.physics.force_kernels.spring_forces_gather",
        ),
        (
            "cloth_sim.constraints.strain_projection.project",
            "cloth_sim.constraints.strain_projection._over_bound",
        ),
        ("cloth_sim.integrators.implicit._pcg", "cloth_sim.integrators.implicit._system_product"),
        ("cloth_sim.integrators.implicit._pcg", "cloth_sim.integrators.implicit._cg_direction"),
        ("cloth_sim.integrators.implicit._pcg", "cloth_sim.integrators.implicit._cg_update"),
    }
