"""cloth_sim survives fork(): what a learning user's process does after it has stepped a cloth.

Each check runs in a fresh interpreter (numba chooses its threading layer once per process, and the
test process's own layer must not decide the outcome). The parent first steps a cloth large enough
that the parallel kernels run (numba's pool is up), then forks: Gymnasium's async vector env, a
``multiprocessing`` fork pool, a bare ``os.fork()``. Under GNU OpenMP (numba's default on Linux)
each of these children is killed ("fork() called from a process already using GNU OpenMP").
"""

import os
import subprocess
import sys
import textwrap

import pytest

#: the parent's part: a 48×48 cloth (its spring forces run on the parallel gather) stepped, and the
#: threading layer numba chose is a fork-safe one
PARENT = """
import numba
import numpy as np
from cloth_sim.scene import load_scene

sim = load_scene("hanging_provot").build_simulator(rows=48, cols=48, spacing=1.0 / 47)
sim.step(20)
layer = numba.threading_layer()
assert layer in ("tbb", "workqueue"), layer
saved = sim.save_state()


def child_steps():
    # 20 steps from the state the parent had when it forked
    sim.restore_state(saved)
    sim.step(20)
    return float(np.abs(sim.positions).sum())
"""


def run(body: str, timeout=240) -> subprocess.CompletedProcess:
    env = {
        k: v for k, v in os.environ.items() if k != "NUMBA_THREADING_LAYER"
    }  # cloth_sim's choice
    code = textwrap.dedent(PARENT) + textwrap.dedent(body)
    p = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=timeout
    )
    assert p.returncode == 0, (p.stdout + p.stderr)[-3000:]
    return p


def test_a_bare_fork_child_steps_the_same_cloth(tmp_path):
    out = tmp_path / "child.txt"
    p = run(f"""
        import os

        pid = os.fork()
        if pid == 0:
            value = child_steps()
            with open({str(out)!r}, "w") as f:
                f.write(repr(value))
            os._exit(0)
        _, status = os.waitpid(pid, 0)
        assert os.waitstatus_to_exitcode(status) == 0, status
        # the parent steps its own copy the same 20 steps: the child's cloth is the same bits
        assert repr(child_steps()) == open({str(out)!r}).read()
        print("ok", layer)
    """)
    assert p.stdout.startswith("ok")


def test_a_multiprocessing_fork_pool_steps_in_its_workers():
    p = run(
        """
        import multiprocessing as mp


        def step_in_worker(_):
            return child_steps()


        with mp.get_context("fork").Pool(2) as pool:
            values = pool.map(step_in_worker, range(4), chunksize=1)
        assert len(set(values)) == 1, values  # each task stepped from the inherited state
        print("ok", layer)
    """,
        timeout=120,
    )
    assert p.stdout.startswith("ok")


def test_gymnasiums_async_vector_env_after_the_parent_stepped_an_env():
    pytest.importorskip("gymnasium")
    p = run("""
        import gymnasium as gym
        import cloth_sim.envs  # noqa: F401

        env = gym.make("cloth_sim/ClothDrop-v0")
        env.reset(seed=0)
        env.step(env.action_space.sample())
        vec = gym.make_vec("cloth_sim/ClothDrop-v0", num_envs=2, vectorization_mode="async")
        try:
            obs, _ = vec.reset(seed=1)
            obs, reward, terminated, truncated, info = vec.step(vec.action_space.sample())
            assert reward.shape == (2,)
        finally:
            vec.close()
        print("ok", layer)
    """)
    assert p.stdout.startswith("ok")
