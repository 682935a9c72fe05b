"""What the adapters' tests share: a Gymnasium task's initial-state cache, one per test session.

A variation is a function of its task, the task's settings and its number alone, written to a
temporary name and renamed (:mod:`cloth_sim.envs.initial_states`), so every test of the session,
in any file and on any pytest-xdist worker, may share one folder: a T-shirt variation (most of a
minute to drop and settle) is made once a session, not once a file and worker. Two workers that
need the same missing variation at once both make it, the same bits, and the last rename wins.
"""

import os

import pytest


@pytest.fixture(scope="session")
def cache(tmp_path_factory):
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # the session's folder, above each worker's own
    folder = root / "initial_states"
    folder.mkdir(exist_ok=True)
    return str(folder)
