"""``cloth-sim bench hashes``: every shipped scene's state after a fixed run, hashed: the check a
step-changing commit passes ("the same bits", docs/contributing.md).

Each scene runs ``steps`` steps on its own integrator and on ``vbd`` (where that is not its own);
its positions and velocities are hashed together (SHA-256, the first 16 hex digits). Run it before
and after a change and ``diff`` the two tables: a refactor or a speed-up keeps every row, and a
commit that changes a row says which and why.

``--fresh-cache`` hashes with kernels compiled from the source as it is now, as ``make install``
compiles them on a fresh clone (its parts side by side, :func:`cloth_sim.kernels.compile_kernels`,
then the run), in an empty numba cache of their own: the table CI's kernels would give. Without
it the kernels come from the package's cache, which :mod:`cloth_sim.kernel_cache` keeps true to
the source (a kernel whose imported files changed compiles again), so the two tables agree.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import tempfile

from ..kernels import COMPILE_PARTS
from ..scene import available_scenes, load_scene

#: the prefix of the child's rows on its standard output
_MARK = "scene-hash: "


def state_hash(sim) -> str:
    """The first 16 hex digits of the SHA-256 of ``sim``'s positions and velocities (their
    bytes: one bit of one coordinate changes it)."""
    digest = hashlib.sha256(sim.positions.tobytes() + sim.velocities.tobytes())
    return digest.hexdigest()[:16]


def scene_hashes(steps: int = 300, scenes=None) -> list[tuple[str, str, str]]:
    """``(scene, integrator, hash)`` for each scene (default: every shipped one) after ``steps``
    steps on its own integrator and on ``vbd``; a scene that fails gets its error in the hash's
    place."""
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    rows = []
    for name in scenes or available_scenes():
        scene = load_scene(name)
        for integrator in dict.fromkeys((scene.integrator, "vbd")):
            try:
                own = integrator == scene.integrator
                sim = (
                    scene.build_simulator()
                    if own
                    else scene.build_simulator(integrator=integrator)
                )
                sim.step(steps)
                digest = state_hash(sim)
            except Exception as e:  # (reported in its row; the other scenes still run)
                digest = f"error: {type(e).__name__}: {e}"
            rows.append((name, integrator, digest))
    return rows


def _compile_fresh(cache: str) -> None:
    """``make install``'s compilation into ``cache``: the parts side by side."""
    env = {**os.environ, "NUMBA_CACHE_DIR": cache}
    code = (
        "import sys; from cloth_sim.kernels import compile_kernels; compile_kernels(sys.argv[1])"
    )
    procs = [
        subprocess.Popen([sys.executable, "-c", code, part], env=env) for part in COMPILE_PARTS
    ]
    if any(p.wait() != 0 for p in procs):
        raise RuntimeError("compiling the kernels into a fresh cache failed")


def fresh_scene_hashes(steps: int = 300, scenes=None) -> list[tuple[str, str, str]]:
    """:func:`scene_hashes` with kernels compiled from the source in an empty cache (module
    docstring), in a child process."""
    with tempfile.TemporaryDirectory(prefix="cloth_sim_hashes_") as cache:
        _compile_fresh(cache)
        out = subprocess.run(
            [sys.executable, "-m", "cloth_sim.bench.scene_hashes", str(steps), *(scenes or ())],
            env={**os.environ, "NUMBA_CACHE_DIR": cache},
            stdout=subprocess.PIPE,
            text=True,
            check=True,
        ).stdout
    return [
        tuple(line[len(_MARK) :].split("\t"))
        for line in out.splitlines()
        if line.startswith(_MARK)
    ]


def print_scene_hashes(steps: int = 300, scenes=None, fresh_cache: bool = False) -> None:
    """Print the table (``diff`` two of them)."""
    rows = (fresh_scene_hashes if fresh_cache else scene_hashes)(steps, scenes)
    where = "kernels compiled into a fresh cache" if fresh_cache else "kernels from the cache"
    print(f"# every scene after {steps} steps, on its own integrator and on vbd; {where}")
    for name, integrator, digest in rows:
        print(f"{name:24s} {integrator:18s} {digest}")


if __name__ == "__main__":  # the child of fresh_scene_hashes
    for row in scene_hashes(int(sys.argv[1]), sys.argv[2:] or None):
        print(_MARK + "\t".join(row), flush=True)
