"""A compiled kernel that calls a parallel one, loaded from numba's cache into a fresh process,
runs (:mod:`cloth_sim.threads`): RK4's fused step once crashed there (numba/numba#8578)."""

import os
import subprocess
import sys

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
