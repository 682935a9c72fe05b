"""Initial states, generated once per variation and kept on disk.

Variation ``i`` of a task is made by the task's generator from ``numpy.random.default_rng([task id,
i])`` (SoftGym's ``generate_env_variation``, one variation at a time), so it depends on the task,
its settings and ``i`` alone: generating it again anywhere gives the same float64 state bit for
bit, and a cached one is that state. The cache is a folder per task and settings (a hash of them
and of :data:`VERSION`) under ``$CLOTH_SIM_CACHE`` or ``~/.cache/cloth_sim/initial_states``, a
``.npz`` per variation written to a temporary name and renamed, so processes sharing it (vector
envs, parallel test workers) never read half a file; and made under a lock of its own (``i.lock``
beside it, :func:`fcntl.flock`), so processes asking for the same missing variation at once make
it once, the others waiting for it (a T-shirt variation is ~20 s of dropping and settling).
``cache_dir=False`` keeps them in memory only.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import tempfile
from pathlib import Path

try:
    import fcntl
except ImportError:  # (no POSIX locks: each process makes what it misses, the same bits)
    fcntl = None

import numpy as np

#: bump when a generator changes what it makes
VERSION = 1


def default_dir() -> Path:
    root = os.environ.get("CLOTH_SIM_CACHE")
    return Path(root) if root else Path.home() / ".cache" / "cloth_sim" / "initial_states"


class Cache:
    """``get(i)`` → the dict of arrays of variation ``i`` (made by ``generate(rng)`` when
    missing)."""

    def __init__(self, task: str, key: dict, generate, cache_dir=None):
        self.task, self.generate = task, generate
        self.key = dict(key, version=VERSION)
        digest = hashlib.sha256(json.dumps(self.key, sort_keys=True).encode()).hexdigest()[:16]
        self.task_id = int.from_bytes(hashlib.sha256(task.encode()).digest()[:4], "little")
        if cache_dir is False:
            self.folder = None
        else:
            self.folder = (
                default_dir() if cache_dir is None else Path(cache_dir)
            ) / f"{task}-{digest}"
        self._memory: dict = {}

    def get(self, i: int) -> dict:
        if i in self._memory:
            return self._memory[i]
        path = None if self.folder is None else self.folder / f"{i}.npz"
        state = self._read(path)
        if state is None:
            with self._locked(path):
                state = self._read(path)  # made meanwhile by the process that held the lock
                if state is None:
                    state = self.generate(np.random.default_rng([self.task_id, i]))
                    if path is not None:
                        self._write(path, state)
        if len(self._memory) > 64:
            self._memory.clear()
        self._memory[i] = state
        return state

    @staticmethod
    def _read(path: Path | None) -> dict | None:
        if path is None or not path.exists():
            return None
        try:
            with np.load(path) as f:
                return {k: f[k] for k in f.files}
        except (OSError, ValueError):  # unreadable: made again
            return None

    @staticmethod
    @contextlib.contextmanager
    def _locked(path: Path | None):
        """Variation ``path``'s own lock, held while it is made (none in memory only)."""
        if path is None or fcntl is None:
            yield
            return
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path.with_suffix(".lock"), "a") as f:
            fcntl.flock(f, fcntl.LOCK_EX)
            try:
                yield
            finally:
                fcntl.flock(f, fcntl.LOCK_UN)

    def _write(self, path: Path, state: dict) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        (path.parent / "settings.json").write_text(json.dumps(self.key, sort_keys=True, indent=1))
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}-", suffix=".npz")
        try:
            with os.fdopen(fd, "wb") as f:
                np.savez(f, **state)
            os.replace(tmp, path)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise
