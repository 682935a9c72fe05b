"""Initial states, generated once per variation and kept on disk.

Variation ``i`` of a task is made by the task's generator from ``numpy.random.default_rng([task id,
i])`` (SoftGym's ``generate_env_variation``, one variation at a time), so it depends on the task,
its settings and ``i`` alone: generating it again anywhere gives the same float64 state bit for
bit, and a cached one is that state. The cache is a folder per task and settings (a hash of them
and of :data:`VERSION`) under ``$CLOTH_SIM_CACHE`` or ``~/.cache/cloth_sim/initial_states``, a
``.npz`` per variation written to a temporary name and renamed, so processes sharing it (vector
envs) never read half a file. ``cache_dir=False`` keeps them in memory only.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path

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
        state = None
        if path is not None and path.exists():
            try:
                with np.load(path) as f:
                    state = {k: f[k] for k in f.files}
            except (OSError, ValueError):  # unreadable: made again below
                state = None
        if state is None:
            state = self.generate(np.random.default_rng([self.task_id, i]))
            if path is not None:
                self._write(path, state)
        if len(self._memory) > 64:
            self._memory.clear()
        self._memory[i] = state
        return state

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
